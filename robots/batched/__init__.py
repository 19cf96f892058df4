"""The batched e-puck simulator: many robots and seeds stepped together by compiled kernels
(numba), validated against the pybullet reference (robots/README.md, "The batched simulator").

* :class:`dfrl.robots.batched.world.BatchedWorld`: the environment of ``n`` robots;
* :class:`dfrl.robots.batched.training.BatchedTrainer`: ``n`` tabular learners training in it;
* :mod:`dfrl.robots.batched.evaluation`: greedy evaluation of many tables at once.
"""
