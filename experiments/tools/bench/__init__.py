"""Benchmarks (``dfrl bench NAME``): each module's function runs one and returns its figures.

* :mod:`.migrate` -- agent migration between two ``swipl`` processes, ms per hop
  (``bench_migrate.pl`` beside it);
* :mod:`.sim` -- simulation + learning speed, steps per second and real-time factor;
* :mod:`.bridge` -- an agent's table read+write through the bridge while a simulation runs;
* :mod:`.round` -- one full dFRL round over N robot node processes.
"""
