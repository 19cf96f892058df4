"""One robot process of a federated experiment (a package: one module per job).

``python -m dfrl.experiments.robot_host --config NODE.json`` embeds SWI-Prolog (``pybridge``),
loads the platform and the dFRL agent program, starts a platform node on loopback, registers
its robot (a :class:`dfrl.robots.training.Trainer`) and prints one line::

    DFRL_NODE <robot> <host> <port>

Then it runs the control loop, one ``trainer.step()`` per iteration, and appends a row per
iteration to ``metrics_<robot>.csv`` in the results folder. Table requests of the visiting
agent are served according to the pacing mode (:class:`Mode`):

* ``async`` (default): ``serve_pending()`` once per step; robots never wait for the agent.
* ``sync``: at every respite boundary (iteration ``k * respite``, and the last iteration)
  the robot stops stepping and serves until one ``set_q_table`` has been applied; between
  boundaries it serves nothing, so the agent's reads block until the robot reaches the
  boundary. Same config and seed give the same curves.

Every applied ``set_q_table`` appends a row to ``shares_<robot>.csv``: the share index, the
iteration, the wall time, the sha256 of the table's float64 bytes right after the set, the
write's round, agent and epoch, and ``q_sum``, the sum the set left (a function learner's:
its parameters'; the metrics row of that iteration was written before the set).

Other lines on stdout, for the launcher's progress display::

    DFRL_PROGRESS <robot> <iteration>
    DFRL_EVENT <robot> get|set <iteration>
    DFRL_SAMPLE <robot> <iteration> <x> <y> <yaw> <q_sum> <cumulative_reward>
    DFRL_EVAL <robot> <iteration> <collisions_per_1000> <progress> <coverage>
    DFRL_DONE <robot> <iterations> <shares>

Real-time pacing (``rtf``): one iteration per ``control_dt / rtf`` seconds of wall time,
``control_dt`` being the trainer's own control period (``SimConfig.control_dt``, 64 ms by
default).

With ``eval_every`` > 0 the node measures its greedy policy every so many iterations in an
environment of its own (``eval_<robot>.csv``, a ``DFRL_EVAL`` line; :mod:`.evaluate`).

Modules: :mod:`.process` (the spawned node's life cycle, ``main``), :mod:`.training` (one
experiment: trainer, files, the control loop one iteration at a time), :mod:`.service`
(``dfrl robot``: the same robot as a long-lived service configured over the platform),
:mod:`.checkpoint` (atomic checkpoints at every share and at the end), :mod:`.table` (the
provider registered with the bridge: the trainer's table, or a static one for benchmarks, plus
share bookkeeping with each write's round, agent and epoch), :mod:`.static_robot` (a
benchmark's robot without a simulation, asked for by ``bench_table`` or ``bench_params``),
:mod:`.files` (the CSV files), :mod:`.lines` (stdout protocol, stdin watch), :mod:`.evaluate`
(greedy evaluations while learning).

The node stops early when stdin reaches end of file or reads a line ``stop`` (the launcher
closes it when the experiment ends), unless stdin was at end of file from the start; after
the last iteration it keeps its platform up until no agent is left on it (sync) or until
stdin closes (async), at most ``grace_s`` seconds.
"""

from __future__ import annotations

from dfrl.experiments.robot_host.files import METRIC_FIELDS, SHARE_FIELDS, table_digest
from dfrl.experiments.robot_host.process import RobotProcess, main

__all__ = ["METRIC_FIELDS", "SHARE_FIELDS", "RobotProcess", "main", "table_digest"]
