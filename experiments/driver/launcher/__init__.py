"""Launching a federated experiment on loopback: processes and their lifecycle.

``run(config, output_dir) -> Results`` (:mod:`.run`). Its steps: robot node processes
(:mod:`.children`, :class:`RobotChild`), starting nodes and agents (:mod:`.spawn`), following
the run (:mod:`.monitor`), robots joining (:mod:`.joins`), stopping (:mod:`.shutdown`), all on
one :class:`RunState` (:mod:`.state`). Agents are launched and sent control commands in
:mod:`.agents` only; :mod:`.remote` acts on a running experiment from another process.
"""
from __future__ import annotations

from dfrl.experiments.driver.launcher.agents import (agent_name, launch_agent, open_console,
                                             send_control, swipl_path)
from dfrl.experiments.driver.launcher.children import RobotChild, await_ready
from dfrl.experiments.driver.launcher.remote import inject_method, join_robot, nodes_of
from dfrl.experiments.driver.launcher.run import Launcher, run
from dfrl.experiments.driver.results.summary import Results

__all__ = ["Launcher", "Results", "RobotChild", "agent_name", "await_ready", "inject_method",
           "join_robot", "launch_agent", "nodes_of", "open_console", "run", "send_control", "swipl_path"]
