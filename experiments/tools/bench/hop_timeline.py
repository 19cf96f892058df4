"""Where a hop's time goes: the platform's hop probes, read back as one timeline.

``dfrl bench migrate --timeline`` runs the benchmark once more with the platform compiled with
its probes (``platform_pl/hop_probe.pl``: ``DFRL_HOP_PROBE`` set in both node processes).
Each probe stamps a point of the hand-over in the process that passes it:

* source (the agent's thread): ``move_called``, ``prepared`` (record exported, connection
  taken), ``transfer_sent``, ``answer_read`` (the ``ok(staged)`` answer), ``committed``,
  ``commit_sent``;
* destination, the connection's worker: ``frame_arrived`` (its first byte is there),
  ``frame_read``, ``checked`` (the code check), ``installed``, ``staged``, ``replied``, for the
  transfer; then ``frame_arrived``, ``frame_read``, ``activated``, ``dispatched`` (to an agent
  worker) and ``replied`` for the commit;
* destination, the agent's worker: ``run_started``, ``bounds_entering``, ``handler_called``
  (the hop's end as the benchmark times it).

:func:`timeline` puts the stamps of every hop after the warm-up on one axis, from the hop's
``move_called``, and takes each point's median: the steps between consecutive points are where
the time goes, untouched by the wrappers ``--trace`` puts around predicates (some 10 us a
call). A probe costs one ``assertz/1`` (some 2 us), so the probed run's hop is a little slower
than the timed one; both medians are printed. Without the variable the probes are compiled to
``true``.
"""
from __future__ import annotations

import statistics
import tempfile
from dataclasses import dataclass
from pathlib import Path

from dfrl.experiments.tools.bench import migrate

SOURCE_POINTS = ("move_called", "prepared", "transfer_sent", "answer_read", "committed",
                 "commit_sent")
"""The points the source process stamps in the agent's thread, in their order."""

#: destination points stamped once per frame: labelled with the frame's request
PER_FRAME = ("frame_arrived", "frame_read", "replied")
FRAMES = ("transfer", "commit")
END = "handler_called"


@dataclass
class Point:
    """One point of the hop: its median time from ``move_called`` over the hops that passed
    it, and the step from the point before it (ms)."""

    point: str
    side: str
    """``source`` or ``destination``."""
    hops: int
    at_ms: float
    step_ms: float


def read_stamps(probe_dir: str | Path, role: str) -> list[tuple[float, str]]:
    """The stamps ``(seconds, point)`` a process wrote to ``probe_dir/role.probe``."""
    path = Path(probe_dir) / f"{role}.probe"
    stamps = []
    for n, line in enumerate(path.read_text().splitlines(), start=1):
        words = line.split()
        if len(words) != 2:
            raise ValueError(f"{path}:{n}: expected 'point seconds', got {line!r}")
        stamps.append((float(words[1]), words[0]))
    return sorted(stamps)


def timeline(probe_dir: str | Path, warmup: int = 2,
             roles: tuple[str, str] = ("home", "peer")) -> list[Point]:
    """The median timeline of the hops probed into ``probe_dir`` (both processes' files),
    leaving out the first ``warmup`` hops and any hop whose end (``handler_called`` at the
    destination) is missing, in the order of the medians (the destination's answer to the
    commit and the start of the agent run side by side, so either may come first)."""
    files = {role: read_stamps(probe_dir, role) for role in roles}
    starts = sorted((t, role) for role, stamps in files.items()
                    for t, p in stamps if p == "move_called")
    at: dict[tuple[str, str], list[float]] = {}
    for i, (t0, source) in enumerate(starts):
        if i < warmup:
            continue
        t_next = starts[i + 1][0] if i + 1 < len(starts) else float("inf")
        dest = next(r for r in roles if r != source)
        hop = _one_hop(files[source], files[dest], t0, t_next)
        if hop is not None:
            for key, t in hop.items():
                at.setdefault(key, []).append((t - t0) * 1000)
    hops = max((len(v) for v in at.values()), default=0)
    rows = sorted(((statistics.median(v), side, point, len(v))
                   for (side, point), v in at.items() if len(v) >= hops // 2))
    points: list[Point] = []
    before = 0.0
    for median, side, point, n in rows:
        points.append(Point(point, side, n, median, median - before))
        before = median
    return points


def _one_hop(source: list[tuple[float, str]], dest: list[tuple[float, str]], t0: float,
             t_next: float) -> dict[tuple[str, str], float] | None:
    """The points of the hop that started at ``t0`` (the next one starts at ``t_next``): the
    source's own points and the destination's (its answer to the commit may come after the
    handler started); None if the destination did not reach ``handler_called``."""
    hop: dict[tuple[str, str], float] = {}
    for t, p in source:
        if t0 <= t < t_next and p in SOURCE_POINTS and ("source", p) not in hop:
            hop[("source", p)] = t
    frames = {p: 0 for p in PER_FRAME}
    for t, p in dest:
        if t < t0 or t >= t_next:
            continue
        if p in PER_FRAME:
            if frames[p] >= len(FRAMES):
                continue
            label = f"{p} ({FRAMES[frames[p]]})"
            frames[p] += 1
        else:
            label = p
        hop.setdefault(("destination", label), t)
    return hop if ("destination", END) in hop else None


@dataclass
class TimelineRun:
    """A probed run: its hop median and its timeline."""

    floats: int
    median_ms: float
    points: list[Point]


def measure(floats: int, hops: int, warmup: int = 2, payload: str = "packed",
            tls: str | Path | None = None) -> TimelineRun:
    """Run the benchmark with the probes compiled in (no naive hop) and read the timeline."""
    with tempfile.TemporaryDirectory(prefix="dfrl-probe-") as folder:
        result = migrate.run(floats, hops, warmup, naive=False, payload=payload, tls=tls,
                             probe_dir=folder)
        points = timeline(folder, warmup)
    if not points:
        raise RuntimeError("the probed run left no complete hop (were the probes compiled in?)")
    return TimelineRun(floats, result.median_ms, points)


def table(run: TimelineRun) -> str:
    """The timeline as text, one point a line."""
    lines = [f"  timeline of a hop with {run.floats} floats (probed run, median hop "
             f"{run.median_ms:.3f} ms): point, side, ms from move_called, step"]
    for p in run.points:
        lines.append(f"    {p.point:28} {p.side:12} {p.at_ms:8.3f}  +{p.step_ms:7.3f}")
    return "\n".join(lines)
