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

from dfrl.experiments.driver.config import ExperimentConfig
from dfrl.experiments.driver.console_node import ConsoleNode
from dfrl.experiments.driver.launcher.children import RobotChild
from dfrl.experiments.driver.launcher.remote_robots import RemoteRobot, StatusPoller
from dfrl.experiments.driver.results.agent_log import AgentLog
from dfrl.experiments.tools.view.events import append_event

#: Seconds without progress after which a running robot counts as stalled.
STALL_S = 15.0


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
    children: dict[str, RobotChild | RemoteRobot] = field(default_factory=dict)
    agent_at: dict[str, tuple[str, str, int]] = field(default_factory=dict)  # robot, op, it
    agents: dict[str, AgentInfo] = field(default_factory=dict)
    logs: dict[str, AgentLog] = field(default_factory=dict)
    crashed: dict[str, int] = field(default_factory=dict)
    joined: set[str] = field(default_factory=set)
    programs: dict[str, Path] = field(default_factory=dict)  # injected, for robots that join
    killed: set[str] = field(default_factory=set)       # children the launcher itself stopped
    console: ConsoleNode | None = None                  # the experiment's console node
    console_host: str = "127.0.0.1"                     # where it binds; local nodes too
    tls: Path | None = None                             # TLS folder of the console + local nodes
    experiment_id: str = ""                             # remote robots file it under this
    poller: StatusPoller | None = None                  # polls the remote robots' status
    lost: dict[str, str] = field(default_factory=dict)  # robot -> why (crashed, failed, gone)
    stalls: list[str] = field(default_factory=list)
    progress_at: dict[str, tuple[int, float]] = field(default_factory=dict)  # it, since
    stalled: dict[str, float] = field(default_factory=dict)    # robot -> stalled since
    gathered: dict[str, list[str]] = field(default_factory=dict)
    gather_errors: list[str] = field(default_factory=list)
    interrupted: str | None = None
    from_checkpoint: list[str] = field(default_factory=list)  # tables kept from checkpoints
    printed_rounds: dict[str, int] = field(default_factory=dict)
    sampled: dict[str, Any] = field(default_factory=dict)   # robot -> last sample in the view
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
                    log = self.logs.get(name)
                    self._view_event({"kind": "hop", "agent": name, "robot": robot,
                                      "phase": "forward" if op == "get" else "backward",
                                      "round": (len(log.rounds) if log else 0) + 1,
                                      "iteration": iteration})

    def _view_event(self, event: dict) -> None:
        """A line of ``events.jsonl`` for the live view (:mod:`dfrl.experiments.tools.view`); a
        failed write is said, never fatal to the run."""
        try:
            append_event(self.out, event)
        except (OSError, ValueError) as exc:
            self.say(f"could not write events.jsonl: {exc}")

    def view_samples(self) -> None:
        """Each robot's newest ``DFRL_SAMPLE`` not written yet, as a ``pose`` event; for a
        remote robot (its files arrive at the end) also as a ``progress`` event (iteration,
        sum of Q-values, cumulative reward, shares), so that the view's curves follow it.
        Every ``DFRL_EVAL`` a robot wrote since, in order, as an ``eval`` event (robot,
        iteration, progress, collisions_per_1000, coverage)."""
        for rid, ch in self.children.items():
            while ch.evals:
                e = ch.evals.popleft()
                self._view_event({"kind": "eval", "robot": rid, "iteration": e.iteration,
                                  "progress": e.progress,
                                  "collisions_per_1000": e.collisions_per_1000,
                                  "coverage": e.coverage})
            sample = ch.sample
            if sample is None or self.sampled.get(rid) == sample:
                continue
            self.sampled[rid] = sample
            self._view_event({"kind": "pose", "robot": rid, "iteration": sample.iteration,
                              "x": sample.x, "y": sample.y, "yaw": sample.yaw})
            if isinstance(ch, RemoteRobot):
                self._view_event({"kind": "progress", "robot": rid,
                                  "iteration": sample.iteration, "q_sum": sample.q_sum,
                                  "cumulative_reward": sample.cumulative_reward,
                                  "shares": ch.shares})
        for rid, ch in self.children.items():
            why = ch.sample_error if isinstance(ch, RemoteRobot) else None
            if why is not None and self.sampled.get(f"{rid}!") != why:
                self.sampled[f"{rid}!"] = why
                self._view_event({"kind": "error",
                                  "text": f"no live samples from {rid}: {why[:200]}"})

    def remote(self) -> list[RemoteRobot]:
        return [ch for ch in self.children.values() if isinstance(ch, RemoteRobot)]

    def check_children(self) -> None:
        """Record (and say) every robot process that died with a non-zero exit code, every
        remote robot that failed or stopped answering (and came back), and stalls."""
        now = time.monotonic()
        for rid, ch in self.children.items():
            if isinstance(ch, RemoteRobot):
                why = ch.lost
                if why is not None and rid not in self.lost:
                    self.lost[rid] = why
                    self.say(f"ROBOT {rid} LOST at iteration {ch.iteration}: {why}")
                    self._view_event({"kind": "robot_state", "robot": rid, "state": "dead",
                                      "reason": why})
                elif why is None and rid in self.lost and ch.state != "failed":
                    self.say(f"robot {rid} answers again (iteration {ch.iteration})")
                    del self.lost[rid]
                    self._view_event({"kind": "robot_state", "robot": rid, "state": "learning"})
                for t0, t1, reason in ch.take_outages():
                    self.stalls.append(f"{rid} unreachable from {t0 - self.t0:.1f} s to "
                                       f"{t1 - self.t0:.1f} s ({reason[:120]})")
            else:
                rc = ch.exit_code()
                if rc is not None and rc != 0 and rid not in self.crashed \
                        and rid not in self.killed:
                    self.crashed[rid] = rc
                    self.lost[rid] = f"process exited with code {rc}"
                    self._view_event({"kind": "robot_state", "robot": rid, "state": "dead",
                                      "reason": f"exit code {rc}"})
                    self.say(f"ROBOT {rid} CRASHED (exit code {rc}) at iteration "
                             f"{ch.iteration}; see {ch.err_path}\n{ch.err_tail()}")
            self._check_progress(rid, ch, now)

    def _check_progress(self, rid: str, ch: RobotChild | RemoteRobot, now: float) -> None:
        """A running robot whose iteration has not moved for :data:`STALL_S` is stalled; the
        stall is recorded when it moves again (or at the end, :meth:`end_stalls`)."""
        it, since = self.progress_at.get(rid, (-1, now))
        if ch.iteration != it:
            if rid in self.stalled:
                self._stall(rid, self.stalled.pop(rid), now, it)
            self.progress_at[rid] = (ch.iteration, now)
        elif ch.running and not ch.done and ch.iteration < ch.cfg.iterations \
                and now - since > STALL_S and rid not in self.stalled:
            self.stalled[rid] = since
            self.say(f"robot {rid} stalled at iteration {it} for {now - since:.0f} s")

    def _stall(self, rid: str, since: float, until: float, it: int) -> None:
        self.stalls.append(f"{rid} made no progress at iteration {it} from "
                           f"{since - self.t0:.1f} s to {until - self.t0:.1f} s")

    def end_stalls(self) -> None:
        """Record the stalls still going on (the run is ending)."""
        now = time.monotonic()
        for rid, since in list(self.stalled.items()):
            self._stall(rid, since, now, self.progress_at.get(rid, (-1, now))[0])
        self.stalled.clear()

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
