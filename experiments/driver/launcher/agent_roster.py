"""The agents of a running experiment: what the launcher started (:class:`AgentInfo`, listed in
``nodes.json``), what their round logs say, and where each was last seen.

:class:`AgentRoster` owns that state. Threading: the launcher's thread adds agents and reads
their logs; the reader threads of the robot processes report hops
(:meth:`AgentRoster.on_hop`); a test may ask where an agent is (:meth:`AgentRoster.at`). Every
field is guarded by the roster's lock.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from dfrl.experiments.driver.launcher.reporter import Reporter
from dfrl.experiments.driver.launcher.robot_roster import RobotRoster
from dfrl.experiments.driver.results.agent_log import AgentLog, kept_logs, read_rounds_log


@dataclass(frozen=True)
class AgentInfo:
    """An agent the launcher started (listed in ``nodes.json``)."""

    name: str
    algo: str
    method: str
    rounds: int
    rounds_log: str
    itinerary: tuple[dict[str, Any], ...] = field(default_factory=tuple)
    kind: str = "chain"  # the itinerary's: chain, or tree (clones)
    fanout: int = 2

    def to_dict(self) -> dict[str, Any]:
        out = {
            "name": self.name,
            "algo": self.algo,
            "method": self.method,
            "rounds": self.rounds,
            "rounds_log": self.rounds_log,
            "itinerary": [dict(s) for s in self.itinerary],
            "kind": self.kind,
        }
        if self.kind == "tree":
            out["fanout"] = self.fanout
        return out


class AgentRoster:
    """The agents of one run (see the module doc)."""

    def __init__(self, reporter: Reporter) -> None:
        self._say = reporter.say
        self._event = reporter.event
        self._lock = threading.Lock()
        self._agents: dict[str, AgentInfo] = {}
        self._logs: dict[str, AgentLog] = {}
        self._at: dict[str, tuple[str, str, int]] = {}  # agent -> robot, op, iteration
        self._said: dict[str, int] = {}  # agent -> rounds said

    def add(self, info: AgentInfo) -> None:
        with self._lock:
            self._agents[info.name] = info

    def get(self, name: str) -> AgentInfo | None:
        with self._lock:
            return self._agents.get(name)

    def infos(self) -> list[AgentInfo]:
        """Every agent, in the order they were launched."""
        with self._lock:
            return list(self._agents.values())

    def add_stop(self, name: str, stop: dict[str, Any]) -> dict[str, Any]:
        """``stop`` (a robot that joins) ends agent ``name``'s itinerary from now on; returns
        the agent's first stop (where it takes control commands)."""
        with self._lock:
            info = self._agents[name]
            info = self._agents[name] = replace(info, itinerary=(*info.itinerary, dict(stop)))
            return dict(info.itinerary[0])

    def log(self, name: str) -> AgentLog | None:
        """What agent ``name``'s round log said at the last :meth:`read_logs`."""
        with self._lock:
            return self._logs.get(name)

    def logs(self) -> dict[str, AgentLog]:
        with self._lock:
            return dict(self._logs)

    def rounds_done(self, name: str) -> int:
        log = self.log(name)
        return len(log.rounds) if log is not None else 0

    def at(self, name: str) -> tuple[str, str, int] | None:
        """Where agent ``name`` was last seen: (robot, ``get``/``set``, its iteration)."""
        with self._lock:
            return self._at.get(name)

    def on_hop(self, robot: str, algo: str, op: str, iteration: int) -> None:
        """A robot learning with ``algo`` served an agent request (``get``: the agent read its
        table, ``set``: it wrote one): remember where the agent is, tell the live view."""
        with self._lock:
            for name, info in self._agents.items():
                if info.algo == algo or any(s.get("robot") == robot for s in info.itinerary):
                    self._at[name] = (robot, op, iteration)
                    log = self._logs.get(name)
                    self._event(
                        {
                            "kind": "hop",
                            "agent": name,
                            "robot": robot,
                            "phase": "forward" if op == "get" else "backward",
                            "round": (len(log.rounds) if log else 0) + 1,
                            "iteration": iteration,
                        }
                    )

    def read_logs(self, robots: RobotRoster, kept_in: Path | None = None) -> None:
        """Re-read every agent's log; say each round not said yet (with the iterations of the
        agent's robots now). ``kept_in``: a results folder whose robots' kept logs
        (``agent_logs/<robot>/rounds_<agent>.log``) are read too, for lines the console did
        not get (at the end of a run, once the robots' files are gathered)."""
        for info in self.infos():
            kept = kept_logs(kept_in, info.name) if kept_in is not None else []
            log = read_rounds_log(info.rounds_log, info.name, kept=kept)
            with self._lock:
                self._logs[info.name] = log
                shown, self._said[info.name] = self._said.get(info.name, 0), len(log.rounds)
            for rec in log.rounds[shown:]:
                mine = {s.get("robot") for s in info.itinerary}  # (a grid agent's: any algo)
                its = " ".join(
                    f"{rid}:{it}" for rid, it in robots.iterations().items() if rid in mine
                )
                flags = "".join(
                    f" SKIPPED {s.robot} ({' '.join(s.reason.split())[:120]})" for s in rec.skipped
                )
                if rec.failed_method:
                    flags += (
                        f" METHOD {rec.failed_method} FAILED, round done again with "
                        f"{rec.method}: {rec.error[:300]}"
                    )
                elif rec.error:
                    flags += f" METHOD FAILED, round aborted, no table written: {rec.error[:300]}"
                self._say(
                    f"{info.name} round {rec.round}/{info.rounds} {rec.method} "
                    f"{rec.duration_ms:.0f} ms, {rec.hops} hops, visited "
                    f"{','.join(rec.visited) or 'none'}{flags} | {its}"
                )

    def all_finished(self) -> bool:
        """Every agent logged ``finished``."""
        with self._lock:
            return all(
                self._logs.get(n) is not None and self._logs[n].finished is not None
                for n in self._agents
            )

    def where(self) -> list[str]:
        """Per agent: rounds done and where it is (or that it finished), for a status line."""
        with self._lock:
            out = []
            for name, info in self._agents.items():
                log = self._logs.get(name)
                at = self._at.get(name)
                pos = f"{at[0]} ({at[1]})" if at else "-"
                st = "finished" if log and log.finished is not None else f"at {pos}"
                out.append(f"{name} {len(log.rounds) if log else 0}/{info.rounds} rounds, {st}")
            return out
