"""What the view follows of one robot: its metrics and shares files, its pose, its state.

:class:`RobotTrack` reads ``metrics_<robot>.csv`` and ``shares_<robot>.csv`` incrementally and
infers the robot's state from them (a ``robot_state`` event in ``events.jsonl`` overrides the
inference):

* ``done``: it ran all its iterations;
* ``dead``: its process is gone before the end (a local run: the pid in ``nodes.json`` no
  longer exists), or the agent skipped it in the last round and its metrics stopped;
* ``skipped``: the agent skipped it in the last round and it still learns;
* ``waiting``: sync mode, at a respite boundary, its table not written yet;
* ``stalled``: no new iteration for :data:`STALL_S` seconds;
* ``learning``: otherwise.

:func:`arena_event` draws a robot's arena small (floor, blocks, start pose).
"""

from __future__ import annotations

import bisect
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dfrl.experiments.tools.view.tail import CsvTail, file_mtime

#: Seconds without a new iteration after which a robot counts as stalled (as the launcher).
STALL_S = 15.0
#: Seconds without a new iteration after which a skipped robot counts as dead.
DEAD_S = 3.0


def _num(text: str | None) -> float | None:
    try:
        v = float(text) if text not in (None, "") else None
    except ValueError:
        return None
    return v if v is not None and math.isfinite(v) else None


@dataclass
class RobotTrack:
    """One robot as the view follows it.

    Parameters
    ----------
    robot : str
    out : Path
        Results folder.
    target : int
        Iterations it is to run.
    stride : int
        Keep one metrics point in ``stride`` (and the last of each batch).
    """

    robot: str
    out: Path
    target: int
    stride: int = 1
    pid: int | None = None
    respite: int = 0
    local: bool = False
    born: float = 0.0  # when the view learnt of it (nodes.json)
    metrics: CsvTail = field(init=False)
    shares: CsvTail = field(init=False)
    iteration: int = 0
    grew_at: float = 0.0
    shared_at: int = 0  # iteration of the last share
    anchors_it: list[int] = field(default_factory=list)
    anchors_t: list[float] = field(default_factory=list)
    skipped: bool = False  # skipped in the agent's last round
    told: str | None = None  # state from events.jsonl
    state: str | None = None

    def __post_init__(self) -> None:
        self.metrics = CsvTail(self.out / f"metrics_{self.robot}.csv")
        self.shares = CsvTail(self.out / f"shares_{self.robot}.csv")

    def set_start(self, t0: float) -> None:
        """Anchor iteration 0 at wall time ``t0`` (the run's start)."""
        if not self.anchors_it:
            self.anchors_it.append(0)
            self.anchors_t.append(t0)

    def time_of(self, iteration: int) -> float | None:
        """Wall time of ``iteration`` interpolated between shares (None past the last)."""
        k = bisect.bisect_left(self.anchors_it, iteration)
        if k >= len(self.anchors_it):
            return None
        if self.anchors_it[k] == iteration or k == 0:
            return self.anchors_t[k]
        i0, i1 = self.anchors_it[k - 1], self.anchors_it[k]
        t0, t1 = self.anchors_t[k - 1], self.anchors_t[k]
        return t0 + (t1 - t0) * (iteration - i0) / (i1 - i0)

    def read_shares(self) -> list[dict[str, Any]]:
        """Share events for the rows added (``round``/``agent`` None in old files)."""
        out = []
        for row in self.shares.read_rows():
            it, wall = _num(row.get("iteration")), _num(row.get("wall_time"))
            if it is None or wall is None:
                continue
            rnd = _num(row.get("round"))
            ev = {
                "t": wall,
                "kind": "share",
                "robot": self.robot,
                "iteration": int(it),
                "round": int(rnd) if rnd is not None else None,
                "agent": row.get("agent") or None,
            }
            if not self.anchors_it or int(it) > self.anchors_it[-1]:
                self.anchors_it.append(int(it))
                self.anchors_t.append(wall)
            self.shared_at = max(self.shared_at, int(it))
            out.append(ev)
        return out

    def read_metrics(self, now: float) -> list[dict[str, Any]]:
        """Metrics events for the rows added: points ``[iteration, q_sum, cumulative_reward,
        collisions]``, one event per stretch between two shares (timed by the shares)."""
        rows = self.metrics.read_rows()
        if not rows:
            return []
        if self.metrics.tail.restarted:
            self.iteration = 0
        batches: dict[int, list[list[float]]] = {}
        last = None
        for row in rows:
            it = _num(row.get("iteration"))
            q, cr = _num(row.get("q_sum")), _num(row.get("cumulative_reward"))
            if it is None or q is None or cr is None:
                continue
            it_i = int(it)
            self.iteration = max(self.iteration, it_i)
            last = (it_i, [it_i, q, cr, _num(row.get("collisions")) or 0.0])
            if it_i % self.stride == 0 or it_i >= self.target:
                batches.setdefault(bisect.bisect_left(self.anchors_it, it_i), []).append(last[1])
        if last is not None:
            seg = bisect.bisect_left(self.anchors_it, last[0])
            pts = batches.setdefault(seg, [])
            if not pts or pts[-1][0] != last[0]:
                pts.append(last[1])
            self.grew_at = now
        mtime = file_mtime(self.metrics.path) or now
        out = []
        for seg in sorted(batches):
            pts = batches[seg]
            t = self.time_of(int(pts[-1][0]))
            out.append(
                {
                    "t": max(self.born, t if t is not None else mtime),
                    "kind": "metrics",
                    "robot": self.robot,
                    "points": pts,
                }
            )
        return out

    def progressed(self, ev: dict[str, Any], now: float) -> None:
        """A ``progress`` event (a remote robot's status): its iteration and shares."""
        it, shares = _num(str(ev.get("iteration"))), _num(str(ev.get("shares")))
        if it is not None and int(it) > self.iteration:
            self.iteration, self.grew_at = int(it), now
        if shares is not None and self.respite > 0 and shares > 0:
            self.shared_at = max(self.shared_at, min(int(shares) * self.respite, self.target))

    def alive(self) -> bool | None:
        """Whether its local process exists (None: not known)."""
        if not self.local or self.pid is None:
            return None
        try:
            os.kill(self.pid, 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            return True
        return True

    def infer(self, now: float, sync: bool, respite: int, live: bool) -> str:
        """The state the facts say now (see the module docstring)."""
        if self.iteration >= self.target > 0:
            return "done"
        if self.told is not None:
            return self.told
        if not live:
            return "dead" if self.skipped else "learning"
        quiet = now - self.grew_at if self.grew_at else 0.0
        if self.alive() is False:
            return "dead"
        if self.skipped:
            return "dead" if quiet > DEAD_S else "skipped"
        at_boundary = (
            respite > 0
            and self.iteration > 0
            and (self.iteration % respite == 0 or self.iteration >= self.target)
        )
        if sync and at_boundary and self.shared_at < self.iteration:
            return "waiting"
        if quiet > STALL_S:
            return "stalled"
        return "learning"


def arena_event(robot: str, arena: str, out_dir: Path, t: float) -> dict[str, Any]:
    """The robot's arena drawn small: floor, blocks, start pose (or an error event)."""
    from dfrl.arenas import ArenaError, load_arena

    try:
        name = arena
        if not (Path(arena).suffix or Path(arena).exists()) or Path(arena).is_absolute():
            spec = load_arena(arena)
        else:
            spec = load_arena(out_dir / arena if (out_dir / arena).exists() else arena)
    except (ArenaError, OSError) as exc:
        return {"t": t, "kind": "error", "text": f"arena of {robot} not drawn: {exc}"}
    return {
        "t": t,
        "kind": "arena",
        "robot": robot,
        "name": spec.name or name,
        "size": list(spec.size),
        "blocks": [
            {"center": list(b.center), "size": list(b.size[:2]), "yaw": b.yaw} for b in spec.blocks
        ],
        "start": list(spec.start.pose) if spec.start.pose is not None else None,
    }
