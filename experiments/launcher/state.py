"""The state of one running experiment, shared by the launcher's steps.

:class:`RunState` holds the processes, the agents and what their logs say; the steps
(:mod:`.spawn`, :mod:`.monitor`, :mod:`.joins`, :mod:`.shutdown`) are functions of it.
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

from dfrl.experiments.config import ExperimentConfig
from dfrl.experiments.control import ConsoleNode
from dfrl.experiments.launcher.children import RobotChild
from dfrl.experiments.results.agent_log import AgentLog


@dataclass
class AgentInfo:
    """An agent the launcher started (listed in ``nodes.json``)."""

    name: str
    algo: str
    method: str
    rounds: int
    rounds_log: str
    itinerary: list[dict[str, Any]]

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "algo": self.algo, "method": self.method,
                "rounds": self.rounds, "rounds_log": self.rounds_log,
                "itinerary": list(self.itinerary)}


@dataclass
class RunState:
    """Processes, agents and logs of one experiment (see :class:`.run.Launcher`)."""

    config: ExperimentConfig
    out: Path
    progress: TextIO | None
    children: dict[str, RobotChild] = field(default_factory=dict)
    agent_at: dict[str, tuple[str, str, int]] = field(default_factory=dict)  # robot, op, it
    agents: dict[str, AgentInfo] = field(default_factory=dict)
    logs: dict[str, AgentLog] = field(default_factory=dict)
    crashed: dict[str, int] = field(default_factory=dict)
    joined: set[str] = field(default_factory=set)
    killed: set[str] = field(default_factory=set)       # children the launcher itself stopped
    console: ConsoleNode | None = None                  # the experiment's console node
    interrupted: str | None = None
    printed_rounds: dict[str, int] = field(default_factory=dict)
    last_status: float = 0.0
    t0: float = field(default_factory=time.monotonic)
    lock: threading.Lock = field(default_factory=threading.Lock)

    def say(self, text: str) -> None:
        """A progress line (nothing when ``progress`` is None)."""
        if self.progress is not None:
            self.progress.write(text + "\n")
            self.progress.flush()

    def on_event(self, robot: str, op: str, iteration: int) -> None:
        """A robot served an agent request: remember where its agent is."""
        child = self.children.get(robot)
        algo = child.robot.algo if child is not None else None
        with self.lock:
            for name, info in self.agents.items():
                if info.algo == algo:
                    self.agent_at[name] = (robot, op, iteration)

    def check_children(self) -> None:
        """Record (and say) every robot process that died with a non-zero exit code."""
        for rid, ch in self.children.items():
            rc = ch.proc.poll()
            if rc is not None and rc != 0 and rid not in self.crashed and rid not in self.killed:
                self.crashed[rid] = rc
                self.say(f"ROBOT {rid} CRASHED (exit code {rc}) at iteration {ch.iteration}; "
                         f"see {ch.err_path}\n{ch.err_tail()}")

    def all_finished(self) -> bool:
        """Every agent logged ``finished``."""
        return all(self.logs.get(n) is not None and self.logs[n].finished is not None
                   for n in self.agents)

    def all_exited(self) -> bool:
        return all(not ch.running for ch in self.children.values())

    def robots_done(self) -> bool:
        """Every robot ended or ran all its iterations."""
        return all(not ch.running or ch.iteration >= ch.cfg.iterations
                   for ch in self.children.values())
