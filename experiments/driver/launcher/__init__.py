"""Launching a federated experiment: its processes and their lifecycle.

``run(config, output_dir) -> Results`` (:mod:`.experiment`). Every robot is a
:class:`~.robots.Robot`, a process of this host (:mod:`.children`) or a ``dfrl robot`` service
of another (:mod:`.remote_robots`); the launcher's steps use that interface only. Its steps:
starting robots and agents (:mod:`.spawn`), following the run (:mod:`.monitor`), robots
joining (:mod:`.joins`); the run's state lives in :class:`~.robot_roster.RobotRoster` and
:class:`~.agent_roster.AgentRoster`, its progress lines and view events go through
:class:`~.reporter.Reporter` (:mod:`.events`). Agents are launched and sent control commands
in :mod:`.agents` only; :mod:`.remote` acts on a running experiment from another process.
"""

from __future__ import annotations

from dfrl.experiments.driver.launcher.agents import (
    agent_name,
    launch_agent,
    open_console,
    send_control,
)
from dfrl.experiments.driver.launcher.children import RobotChild
from dfrl.experiments.driver.launcher.experiment import Launcher, run
from dfrl.experiments.driver.launcher.remote import inject_method, join_robot, nodes_of
from dfrl.experiments.driver.launcher.remote_robots import RemoteRobot
from dfrl.experiments.driver.launcher.robots import Robot, RobotStatus, await_ready
from dfrl.experiments.driver.results.summary import Results

__all__ = [
    "Launcher",
    "RemoteRobot",
    "Results",
    "Robot",
    "RobotChild",
    "RobotStatus",
    "agent_name",
    "await_ready",
    "inject_method",
    "join_robot",
    "launch_agent",
    "nodes_of",
    "open_console",
    "run",
    "send_control",
]
