"""Benchmarks (``dfrl bench NAME``): each module's function runs one and returns its figures.

* :mod:`.migrate` -- agent migration between two ``swipl`` processes, ms per hop
  (``bench_migrate.pl`` beside it);
* :mod:`.sim` -- simulation + learning speed, steps per second and real-time factor;
* :mod:`.bridge` -- an agent's table read+write through the bridge while a simulation runs;
* :mod:`.round` -- one full dFRL round over N robot processes;
* :mod:`.scale` -- federated runs of growing robot counts: wall time, round time, RSS;
* :mod:`.chaos` -- agents moving among store-backed nodes through :mod:`.fault_proxy`
  under random faults: lost, doubled or unsettled agents;
* :mod:`.hostile` -- hostile peers against a node (attackers in :mod:`.hostile_attacks`,
  :mod:`.hostile_auth_attacks`, :mod:`.hostile_child`; targets in :mod:`.hostile_verdict`).

Their options and output are ``experiments/cli/bench.py`` (``bench_hostile.py``).
"""
