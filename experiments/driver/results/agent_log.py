"""The dFRL agent's round log: one JSON object per line (contract C2), read with :mod:`json`.

Events the agent writes (``platform_pl/dfrl_agent/dfrl_agent.pl``)::

    {"event": "round", "agent": A, "round": N, "start": T0, "end": T1, "hops": H,
     "bytes": B, "method": M, "visited": [R, ...], "skipped": [{"robot": R, "reason": Text}]}
    {"event": "finished", "agent": A, "round": N}
    {"event": "aborted", "agent": A, "round": N, "error": Text}
    {"event": "control", "agent": A, "round": N, "command": Text,
     "status": "applied" | "ignored", "reason": Text}
    {"event": "superseded", "agent": A, "round": N, "epoch": E, "by": E2}
    {"event": "resurrected", "agent": A, "round": N, "epoch": E, "from": "host:port",
     "dead": "host:port"}

A round event may also carry ``retries`` (connection attempts repeated that round) and
``epoch`` (both default to 0), and ``error``: the aggregation method failed or threw that
round. With ``failed_method`` too, the round was started again with ``method`` (the method
the agent falls back to) and finished, every table written; without it the round was
aborted without writing any table.

Times are the agent's ``get_time/1`` floats (a ``control`` event also has its ``time``). A
line that is not one of these objects is kept in :attr:`AgentLog.unreadable` (reported, never
dropped).

Where the lines are: the console node appends them to ``rounds_<agent>.log`` in the results
folder; each robot node also keeps the lines the agent logged there, in
``agent_logs/<robot>/rounds_<agent>.log`` of the robot's own folder (its results folder on
this host, its experiment folder on a robot host, fetched with its other files), and posts
them to the console from a bounded outbox (``platform_pl/dfrl_agent/log_outbox.pl``). A line
posted twice (its first post's reply was lost) or read from both places is the same text:
:func:`read_rounds_log` reads a line identical to one already read once (every event line is
unique by its times or its round).
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


@dataclass(frozen=True)
class Skip:
    """A stop the agent could not visit in a round, and why."""

    robot: str
    reason: str


@dataclass(frozen=True)
class RoundRecord:
    """One ``round`` event of an agent log (``visited`` in forward-pass order)."""

    agent: str
    round: int
    start: float
    end: float
    hops: int
    bytes: int
    method: str
    visited: tuple[str, ...]
    skipped: tuple[Skip, ...] = ()
    retries: int = 0
    epoch: int = 0
    #: the aggregation method failed or threw this round (the message): the round was aborted
    #: and no table written, unless ``failed_method`` is set
    error: str = ""
    #: the method that failed when the round was then done with ``method`` (its fallback),
    #: every table written; empty otherwise
    failed_method: str = ""

    @property
    def aborted(self) -> bool:
        """Its method failed and no table was written."""
        return bool(self.error) and not self.failed_method

    @property
    def duration_ms(self) -> float:
        return (self.end - self.start) * 1000.0


@dataclass(frozen=True)
class Aborted:
    """An ``aborted`` event: the agent stopped in ``round`` because of ``error``."""

    round: int
    error: str


@dataclass(frozen=True)
class ControlEvent:
    """A ``control`` event: a queued command the agent applied or ignored at a round start."""

    round: int
    command: str
    status: str
    reason: str = ""


@dataclass(frozen=True)
class Resurrection:
    """A ``resurrected`` event: the stop ``source`` brought the agent back in ``round`` with
    ``epoch`` because the node ``dead`` it had gone to did not answer."""

    round: int
    epoch: int
    source: str
    dead: str


@dataclass(frozen=True)
class Superseded:
    """A ``superseded`` event: a late copy of the agent (``epoch``) met the higher epoch
    ``by`` of its replacement and purged itself."""

    round: int
    epoch: int
    by: int


@dataclass
class AgentLog:
    """What an agent's rounds log holds so far."""

    agent: str
    rounds: list[RoundRecord] = field(default_factory=list)
    finished: int | None = None
    aborted: list[Aborted] = field(default_factory=list)
    controls: list[ControlEvent] = field(default_factory=list)
    resurrections: list[Resurrection] = field(default_factory=list)
    superseded: list[Superseded] = field(default_factory=list)
    #: rounds logged twice (a late copy and its replacement); the higher epoch is kept in
    #: ``rounds``, the other is listed here
    duplicates: list[RoundRecord] = field(default_factory=list)
    unreadable: list[str] = field(default_factory=list)


def parse_event(line: str) -> dict[str, Any]:
    """One log line as its JSON object.

    Raises
    ------
    ValueError
        The line is not a JSON object with a string ``event``.
    """
    obj = json.loads(line)
    if not isinstance(obj, dict) or not isinstance(obj.get("event"), str):
        raise ValueError(f"not an event object: {line!r}")
    return obj


def _round(agent: str, ev: dict[str, Any]) -> RoundRecord:
    skipped = tuple(Skip(str(s["robot"]), str(s["reason"])) for s in ev.get("skipped", []))
    return RoundRecord(agent, int(ev["round"]), float(ev["start"]), float(ev["end"]),
                       int(ev["hops"]), int(ev["bytes"]), str(ev["method"]),
                       tuple(str(v) for v in ev["visited"]), skipped,
                       int(ev.get("retries") or 0), int(ev.get("epoch") or 0),
                       str(ev.get("error") or ""), str(ev.get("failed_method") or ""))


def _add(log: AgentLog, ev: dict[str, Any]) -> bool:
    """Add event ``ev`` to ``log``; False when it is not a known, well-formed event."""
    if ev.get("agent", log.agent) != log.agent:
        return False
    kind = ev["event"]
    if kind == "round":
        rec = _round(log.agent, ev)
        same = next((i for i, r in enumerate(log.rounds) if r.round == rec.round), None)
        if same is None:
            log.rounds.append(rec)
        elif rec.epoch > log.rounds[same].epoch:
            log.duplicates.append(log.rounds[same])
            log.rounds[same] = rec
        else:
            log.duplicates.append(rec)
    elif kind == "finished":
        log.finished = int(ev["round"])
    elif kind == "aborted":
        log.aborted.append(Aborted(int(ev["round"]), str(ev["error"])))
    elif kind == "control":
        log.controls.append(ControlEvent(int(ev["round"]), str(ev["command"]),
                                         str(ev["status"]), str(ev.get("reason", ""))))
    elif kind == "resurrected":
        log.resurrections.append(Resurrection(int(ev["round"]), int(ev.get("epoch") or 0),
                                              str(ev.get("from", "")), str(ev.get("dead", ""))))
    elif kind == "superseded":
        log.superseded.append(Superseded(int(ev["round"]), int(ev.get("epoch") or 0),
                                         int(ev.get("by") or 0)))
    else:
        return False
    return True


def kept_logs(results_dir: str | Path, agent: str) -> list[Path]:
    """The kept logs of ``agent`` under ``results_dir``: ``agent_logs/<robot>/rounds_<agent>.log``
    of every robot node it logged on (see the module doc), sorted."""
    return sorted(Path(results_dir).glob(f"agent_logs/*/rounds_{agent}.log"))


def read_rounds_log(path: str | Path, agent: str,
                    kept: list[Path] | tuple[Path, ...] = ()) -> AgentLog:
    """Read an agent's rounds log (a missing file is an empty log), and with ``kept`` the
    robot nodes' kept logs too (:func:`kept_logs`): each line once (an identical line read
    again is skipped), rounds sorted by number (the files interleave, and lines posted
    from two nodes may reach the console out of order).

    A torn last line (the agent is still writing it) shows up in ``unreadable`` until the
    next read.
    """
    log = AgentLog(agent)
    seen: set[str] = set()
    for p in (Path(path), *map(Path, kept)):
        if p.is_file():
            _read_into(log, p, seen)
    log.rounds.sort(key=lambda r: r.round)
    return log


def _read_into(log: AgentLog, p: Path, seen: set[str]) -> None:
    for line in p.read_text(encoding="utf-8", errors="replace").splitlines():
        if not line.strip() or line in seen:
            continue
        seen.add(line)
        try:
            known = _add(log, parse_event(line))
        except (ValueError, KeyError, TypeError):
            known = False
        if not known:
            log.unreadable.append(line)
