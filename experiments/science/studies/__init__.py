"""Studies that answer a question with several seeds and intervals: the hyper-parameter sweep
(:mod:`.sweep`), the speed-up against the number of robots (:mod:`.speedup`, on the
in-process federation of :mod:`.fedsim`, or :mod:`.fedsim_batched` on the batched simulator:
:mod:`.simulators`) and greedy evaluations of a run's table history (:mod:`.history`). Their
intervals are :mod:`dfrl.experiments.science.statistics`."""
