"""The view's event source: a results folder, read as it grows, turned into events in order.

:meth:`EventSource.poll` reads what was added to the folder's files since the last call (each
file from where its last read stopped, at most :data:`~dfrl.experiments.tools.view.tail.MAX_BYTES` a
file and call; ``config.json`` and ``nodes.json`` again only when they change) and returns the
new events, each a dict with ``seq`` (0, 1, ...), ``t`` (wall clock) and ``kind``:

=============== ==============================================================================
``run``         name, iterations, respite, mode, seed, robots, stride (from ``config.json``)
``robot``       robot, host, port, arena, algo, node, joined (``nodes.json``; a later one: a join)
``arena``       robot, name, size, blocks ``[{center, size, yaw}]``, start ``[x, y, yaw]``
``agent``       agent, algo, method, rounds, itinerary (robot ids), itinerary_kind (chain, tree)
``hop``         agent, robot, phase (forward/backward), round, inferred (not seen, deduced);
                a tree agent's also clone (a copy at that robot, not the agent at the root)
``round``       agent, round, start, end, duration_ms, method, visited, skipped, hops, epoch
``method``      agent, round, method, previous: the agent switched methods
``skip``        agent, round, robot, reason
``share``       robot, iteration, round, agent: the agent wrote the robot's table
``metrics``     robot, points ``[[iteration, q_sum, cumulative_reward, collisions], ...]``
``robot_state`` robot, state, inferred
``pose``        robot, iteration, x, y, yaw (only from ``events.jsonl``)
``progress``    robot, iteration, q_sum, cumulative_reward, shares: a remote robot's status
                (only from ``events.jsonl``; its files arrive at the end of the run)
``eval``        robot, iteration, progress, collisions_per_1000, coverage: a greedy evaluation
                (``eval_every``; the launcher writes one per ``DFRL_EVAL`` line), progress
                drawn as a third curve (only from ``events.jsonl``)
``finished`` ``aborted`` ``control`` ``resurrected`` ``superseded``: the agent's log events
``error``       text: something the view could not read
``run_end``     the run wrote ``summary.md``
=============== ==============================================================================

Every round of an agent's log comes with its hops, before it: forward over ``visited`` in
order, then backward in reverse. Hops come from ``events.jsonl`` when the launcher writes
them, else from the shares files (a table write is a backward hop); the ones not seen are
deduced (``inferred``) from the itinerary, at the latest when the round is logged. A tree
agent's copies read and write at every robot at once: its hops come in the order seen, none
deduced before another.
"""

from __future__ import annotations

import heapq
import json
import time
from pathlib import Path
from typing import Any

from dfrl.experiments.driver.launcher.events import EVENTS_FILE
from dfrl.experiments.tools.view.robots import RobotTrack, arena_event
from dfrl.experiments.tools.view.tail import MAX_BYTES, FileTail, file_mtime

#: Points kept per robot curve, about (the stride is ``iterations // POINTS``).
POINTS = 500
#: Bytes read from one file in one poll at most while draining a finished run (read whole,
#: so that its rounds, hops and poses are ordered by time across the files).
DRAIN_BYTES = 64 * 1024 * 1024
_AGENT_EVENTS = ("finished", "aborted", "control", "resurrected", "superseded")


class _Round:
    """Hops of one round of one agent seen so far."""

    def __init__(self) -> None:
        self.done: set[tuple[str, str]] = set()  # (phase, robot)
        self.closed = False


class EventSource:
    """Events of one results folder; see the module docstring.

    Parameters
    ----------
    results_dir : str or Path
    clock : callable
        Wall clock (``time.time``).
    """

    def __init__(self, results_dir: str | Path, clock: Any = time.time) -> None:
        self.dir = Path(results_dir)
        self.clock = clock
        self.events: list[dict[str, Any]] = []
        self.run: dict[str, Any] | None = None
        self.robots: dict[str, RobotTrack] = {}
        self.agents: dict[str, dict[str, Any]] = {}
        self._nodes_mtime: float | None = None
        self._logs: dict[str, FileTail] = {}
        self._methods: dict[str, str] = {}
        self._rounds: dict[tuple[str, int], _Round] = {}
        self._skipped: dict[str, set[str]] = {}  # agent -> skipped in its last round
        self._last_end: dict[str, float] = {}  # agent -> end of its last round
        self._extra = FileTail(self.dir / EVENTS_FILE)
        self._ended = False
        self._bulk = False

    # -- public ------------------------------------------------------------------------
    @property
    def live(self) -> bool:
        """False once the run wrote its ``summary.md``."""
        return not self._ended

    def poll(self) -> list[dict[str, Any]]:
        """Read what the folder's files gained; the new events, numbered and kept."""
        return self._number(self._collect())

    def drain(self, max_polls: int = 100_000) -> list[dict[str, Any]]:
        """Poll until no file has unread bytes (a finished run); each file is read whole
        (up to :data:`DRAIN_BYTES`) in the first poll, so the events come in time order across
        the files; metrics events are merged into the others by time."""
        got: list[dict[str, Any]] = []
        self._bulk = True  # each file read whole: one poll orders everything by time
        try:
            for _ in range(max_polls):
                got += self._collect()
                if not self._pending():
                    break
            got += self._collect()
        finally:
            self._bulk = False
            self._widen(MAX_BYTES)
        curves = sorted((e for e in got if e["kind"] == "metrics"), key=lambda e: e["t"])
        rest = [e for e in got if e["kind"] != "metrics"]
        return self._number(list(heapq.merge(rest, curves, key=lambda e: e["t"])))

    # -- reading -----------------------------------------------------------------------
    def _number(self, new: list[dict[str, Any]]) -> list[dict[str, Any]]:
        for ev in new:
            ev["seq"] = len(self.events)
            self.events.append(ev)
        return new

    def _tails(self) -> list[FileTail]:
        tails = [self._extra, *self._logs.values()]
        return tails + [t for r in self.robots.values() for t in (r.metrics.tail, r.shares.tail)]

    def _pending(self) -> bool:
        return any(t.pending() for t in self._tails())

    def _widen(self, max_bytes: int) -> None:
        for tail in self._tails():
            tail.max_bytes = max_bytes

    def _collect(self) -> list[dict[str, Any]]:
        out: list[dict[str, Any]] = []
        now = self.clock()
        if self.run is None:
            self._read_config(out)
        if self.run is not None:
            self._read_nodes(out)
            if self._bulk:
                self._widen(DRAIN_BYTES)
            timed = self._read_extra(out)
            for track in self.robots.values():
                timed += [(e["t"], "share", e) for e in track.read_shares()]
            for agent in self.agents:
                timed += self._read_log(out, agent)
            timed.sort(key=lambda item: item[0])  # stable: a file's own order is kept
            for _, what, ev in timed:
                self._apply(out, what, ev)
            for track in self.robots.values():
                out += track.read_metrics(now)
            if not self._ended and (self.dir / "summary.md").is_file():
                self._ended = True
                out.append({"t": file_mtime(self.dir / "summary.md") or now, "kind": "run_end"})
            self._states(out, now)
        return out

    def _read_config(self, out: list[dict[str, Any]]) -> None:
        path = self.dir / "config.json"
        try:
            cfg = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return
        its = int(cfg.get("iterations") or 0)
        self.run = {
            "t": file_mtime(path) or self.clock(),
            "kind": "run",
            "name": cfg.get("name"),
            "iterations": its,
            "respite": int(cfg.get("respite") or 0),
            "mode": cfg.get("mode"),
            "seed": cfg.get("seed"),
            "robots": len(cfg.get("robots") or []),
            "stride": max(1, its // POINTS),
        }
        out.append(self.run)

    def _read_nodes(self, out: list[dict[str, Any]]) -> None:
        path = self.dir / "nodes.json"
        mtime = file_mtime(path)
        if (
            mtime is None
            or mtime == self._nodes_mtime
            or (self.run is not None and mtime < self.run["t"])
        ):
            return  # unchanged, or an older run's
        try:
            nodes = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return  # being written: next time
        self._nodes_mtime = mtime
        assert self.run is not None
        for n in nodes.get("nodes", []):
            rid = str(n["robot"])
            if rid not in self.robots:
                self._add_robot(out, n, mtime)
        for a in nodes.get("agents", []):
            name = str(a["name"])
            if name not in self.agents:
                stops = [str(s["robot"]) for s in a.get("itinerary", [])]
                kind = str(a.get("kind") or "chain")
                self.agents[name] = {"itinerary": stops, "kind": kind}
                self._methods[name] = str(a.get("method"))
                self._logs[name] = FileTail(self.dir / f"rounds_{name}.log")
                out.append(
                    {
                        "t": mtime,
                        "kind": "agent",
                        "agent": name,
                        "algo": a.get("algo"),
                        "method": a.get("method"),
                        "rounds": a.get("rounds"),
                        "itinerary": stops,
                        "itinerary_kind": kind,
                    }
                )

    def _add_robot(self, out: list[dict[str, Any]], n: dict[str, Any], t: float) -> None:
        assert self.run is not None
        rid = str(n["robot"])
        target = self.run["iterations"]
        try:
            node_cfg = json.loads((self.dir / "nodes" / f"{rid}.json").read_text("utf-8"))
            target = int(node_cfg.get("iterations") or target)
        except (OSError, ValueError):
            pass
        local = n.get("robot_host") is None and str(n.get("host", "")).startswith("127.")
        track = RobotTrack(
            rid, self.dir, target, self.run["stride"], n.get("pid"), self.run["respite"], local, t
        )
        track.set_start(self.run["t"])
        self.robots[rid] = track
        out.append(
            {
                "t": t,
                "kind": "robot",
                "robot": rid,
                "host": n.get("host"),
                "port": n.get("port"),
                "arena": n.get("arena"),
                "algo": n.get("algo"),
                "robot_host": n.get("robot_host"),
                "joined": bool(n.get("joined")),
                "iterations": target,
            }
        )
        out.append(arena_event(rid, str(n.get("arena")), self.dir, t))

    def _read_extra(self, out: list[dict[str, Any]]) -> list[tuple[float, str, Any]]:
        """Timed items of the lines added to ``events.jsonl`` (bad lines: error events)."""
        timed: list[tuple[float, str, Any]] = []
        for line in self._extra.read_lines():
            try:
                ev = json.loads(line)
                if not isinstance(ev.get("kind"), str):
                    raise ValueError("no kind")
                ev["t"] = float(ev.get("t", self.clock()))
            except (ValueError, TypeError, AttributeError):
                out.append(
                    {
                        "t": self.clock(),
                        "kind": "error",
                        "text": f"{EVENTS_FILE}: unreadable line {line[:200]!r}",
                    }
                )
                continue
            timed.append((ev["t"], "extra", ev))
        return timed

    def _apply(self, out: list[dict[str, Any]], what: str, ev: Any) -> None:
        """Turn one timed item into events."""
        if what == "share":
            out.append(ev)
            if ev["agent"] and ev["round"] is not None:
                self._hop(out, ev["agent"], ev["round"], ev["robot"], "backward", ev["t"], False)
        elif what == "log":
            agent, item = ev
            if item["event"] == "round":
                self._round(out, agent, item)
            else:
                rec = {k: v for k, v in item.items() if k != "event"}
                rec.update(
                    t=self._last_end.get(agent, self.clock()), kind=item["event"], agent=agent
                )
                out.append(rec)
        elif ev["kind"] == "hop":
            try:
                self._hop(
                    out,
                    str(ev["agent"]),
                    int(ev["round"]),
                    str(ev["robot"]),
                    str(ev["phase"]),
                    ev["t"],
                    False,
                )
            except (KeyError, TypeError, ValueError):
                out.append({"t": ev["t"], "kind": "error", "text": f"bad hop event {ev!r}"})
        else:
            if ev["kind"] == "progress" and str(ev.get("robot")) in self.robots:
                self.robots[str(ev["robot"])].progressed(ev, self.clock())
            if ev["kind"] == "robot_state" and str(ev.get("robot")) in self.robots:
                # a told state holds until another is told; "learning" hands the state
                # back to the inference (waiting, skipped, ... follow from the files again)
                told = str(ev.get("state"))
                self.robots[str(ev["robot"])].told = None if told == "learning" else told
                ev["inferred"] = False
                self.robots[str(ev["robot"])].state = told
            out.append(ev)

    def _tree(self, agent: str) -> bool:
        return self.agents.get(agent, {}).get("kind") == "tree"

    def _copy_hop(
        self, agent: str, rnd: int, robot: str, phase: str, t: float, inferred: bool
    ) -> dict[str, Any]:
        """A tree agent's hop: a copy's (``clone``) unless at the root."""
        return {
            **_hop_event(agent, rnd, robot, phase, t, inferred),
            "clone": robot != (self.agents[agent].get("itinerary") or [robot])[0],
        }

    def _hop(
        self,
        out: list[dict[str, Any]],
        agent: str,
        rnd: int,
        robot: str,
        phase: str,
        t: float,
        inferred: bool,
    ) -> None:
        """Emit a hop, and first the ones it implies: the forward pass precedes the backward
        pass, and the backward pass runs from the last stop to the first."""
        r = self._rounds.setdefault((agent, rnd), _Round())
        if r.closed or (phase, robot) in r.done:
            return
        if self._tree(agent):  # copies at every stop at once: no order to infer
            r.done.add((phase, robot))
            out.append(self._copy_hop(agent, rnd, robot, phase, t, inferred))
            return
        stops = [
            s
            for s in self.agents.get(agent, {}).get("itinerary", [])
            if s not in self._skipped.get(agent, set())
        ]
        if phase == "backward" and robot in stops:
            before = [("forward", s) for s in stops] + [
                ("backward", s) for s in reversed(stops[stops.index(robot) + 1 :])
            ]
            for ph, s in before:
                if (ph, s) not in r.done:
                    r.done.add((ph, s))
                    out.append(_hop_event(agent, rnd, s, ph, t, True))
        elif phase == "forward" and robot in stops:
            for s in stops[: stops.index(robot)]:
                if ("forward", s) not in r.done:
                    r.done.add(("forward", s))
                    out.append(_hop_event(agent, rnd, s, "forward", t, True))
        r.done.add((phase, robot))
        out.append(_hop_event(agent, rnd, robot, phase, t, inferred))

    def _read_log(self, out: list[dict[str, Any]], agent: str) -> list[tuple[float, str, Any]]:
        """Timed items of the lines added to an agent's round log (a round at its end, the
        other events just after the round before them)."""
        timed: list[tuple[float, str, Any]] = []
        for line in self._logs[agent].read_lines():
            if not line.strip():
                continue
            try:
                ev = json.loads(line)
                kind = ev["event"]
                if kind == "round":
                    t = float(ev["end"])
                    self._last_end[agent] = t
                elif kind in _AGENT_EVENTS:
                    t = self._last_end.get(agent, self.clock())
                else:
                    raise ValueError(kind)
            except (ValueError, KeyError, TypeError):
                out.append(
                    {
                        "t": self.clock(),
                        "kind": "error",
                        "text": f"rounds_{agent}.log: unreadable line {line[:200]!r}",
                    }
                )
                continue
            timed.append((t, "log", (agent, ev)))
        return timed

    def _round(self, out: list[dict[str, Any]], agent: str, ev: dict[str, Any]) -> None:
        rnd, start, end = int(ev["round"]), float(ev["start"]), float(ev["end"])
        visited = [str(v) for v in ev.get("visited", [])]
        skipped = [
            {"robot": str(s.get("robot")), "reason": str(s.get("reason"))}
            for s in ev.get("skipped", [])
        ]
        r = self._rounds.setdefault((agent, rnd), _Round())
        if not r.closed:
            tree = self._tree(agent)  # a tree's copies leave no order: the writes not seen
            plan = (
                [("backward", s) for s in visited]
                if tree
                else [("forward", s) for s in visited]
                + [("backward", s) for s in reversed(visited)]
            )
            missing = [p for p in plan if p not in r.done]
            for k, (ph, s) in enumerate(missing):
                t = start + (end - start) * (k + 1) / (len(missing) + 1)
                r.done.add((ph, s))
                out.append((self._copy_hop if tree else _hop_event)(agent, rnd, s, ph, t, True))
            r.closed = True
        method = str(ev.get("method"))
        if method != self._methods.get(agent):
            out.append(
                {
                    "t": start,
                    "kind": "method",
                    "agent": agent,
                    "round": rnd,
                    "method": method,
                    "previous": self._methods.get(agent),
                }
            )
            self._methods[agent] = method
        for skip in skipped:
            out.append({"t": end, "kind": "skip", "agent": agent, "round": rnd, **skip})
        self._skipped[agent] = {skip["robot"] for skip in skipped}
        for rid, track in self.robots.items():
            if rid in visited or rid in self._skipped[agent]:
                track.skipped = rid in self._skipped[agent]
        out.append(
            {
                "t": end,
                "kind": "round",
                "agent": agent,
                "round": rnd,
                "start": start,
                "end": end,
                "duration_ms": round((end - start) * 1000.0, 1),
                "method": method,
                "visited": visited,
                "skipped": skipped,
                "hops": int(ev.get("hops") or 0),
                "epoch": int(ev.get("epoch") or 0),
                "error": str(ev.get("error") or ""),
                "failed_method": str(ev.get("failed_method") or ""),
            }
        )

    def _states(self, out: list[dict[str, Any]], now: float) -> None:
        assert self.run is not None
        sync = self.run.get("mode") == "sync"
        for rid, track in self.robots.items():
            state = track.infer(now, sync, self.run["respite"], not self._ended)
            if state != track.state:
                track.state = state
                t = (
                    now
                    if not self._ended
                    else (track.anchors_t[-1] if track.anchors_t else self.run["t"])
                )
                out.append(
                    {
                        "t": t,
                        "kind": "robot_state",
                        "robot": rid,
                        "state": state,
                        "inferred": track.told is None,
                    }
                )


def _hop_event(
    agent: str, rnd: int, robot: str, phase: str, t: float, inferred: bool
) -> dict[str, Any]:
    return {
        "t": t,
        "kind": "hop",
        "agent": agent,
        "round": rnd,
        "robot": robot,
        "phase": phase,
        "inferred": inferred,
    }
