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
  worker) and ``replied`` for the commit (the stamps of frames name their request, so the
  hello and proof of a new connection in the same hop are left out);
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

SOURCE_POINTS = (
    "move_called",
    "prepared",
    "transfer_sent",
    "answer_read",
    "committed",
    "commit_sent",
)
"""The points the source process stamps in the agent's thread, in their order."""

DEST_POINTS = (
    "frame_arrived (transfer)",
    "frame_read (transfer)",
    "checked",
    "installed",
    "staged",
    "replied (transfer)",
    "frame_arrived (commit)",
    "frame_read (commit)",
    "activated",
    "dispatched",
    "replied (commit)",
    "run_started",
    "bounds_entering",
    "handler_called",
)
"""The points the destination stamps, labelled (a frame's by its request: a hop may also see
the hello and proof of a new connection, which are left out)."""


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


def timeline(
    probe_dir: str | Path, warmup: int = 2, roles: tuple[str, str] = ("home", "peer")
) -> list[Point]:
    """The median timeline of the hops probed into ``probe_dir`` (both processes' files of
    the benchmark's bounce), in the order of the medians, over the hops after the first
    ``warmup`` that passed every point of :data:`SOURCE_POINTS` and :data:`DEST_POINTS`.

    Only complete hops count, so every median is taken over the same hops and the medians
    keep the order the points have in each hop. A hop's points are looked for until the
    source's next ``move_called``: a thread preempted after sending may stamp its point after
    the agent has already moved on (the destination answers the commit beside the agent's
    start, so either may come first)."""
    files = {role: read_stamps(probe_dir, role) for role in roles}
    starts = sorted(
        (t, role) for role, stamps in files.items() for t, p in stamps if p == "move_called"
    )
    at: dict[tuple[str, str], list[float]] = {}
    for i, (t0, source) in enumerate(starts):
        if i < warmup:
            continue
        t_end = next((t for t, r in starts[i + 1 :] if r == source), float("inf"))
        dest = next(r for r in roles if r != source)
        hop = _one_hop(files[source], files[dest], t0, t_end)
        if hop is not None:
            for key, t in hop.items():
                at.setdefault(key, []).append((t - t0) * 1000)
    rows = sorted((statistics.median(v), side, point, len(v)) for (side, point), v in at.items())
    points: list[Point] = []
    before = 0.0
    for median, side, point, n in rows:
        points.append(Point(point, side, n, median, median - before))
        before = median
    return points


def _one_hop(
    source: list[tuple[float, str]], dest: list[tuple[float, str]], t0: float, t_end: float
) -> dict[tuple[str, str], float] | None:
    """The points of the hop that started at ``t0``, looked for until ``t_end``: the source's
    own points and the destination's; None if one is missing."""
    hop: dict[tuple[str, str], float] = {}
    for t, p in source:
        if t0 <= t < t_end and p in SOURCE_POINTS:
            hop.setdefault(("source", p), t)
    window = [(t, p) for t, p in dest if t0 <= t < t_end]
    for i, (t, p) in enumerate(window):
        label = _dest_label(p, window[i + 1 :])
        if label is not None:
            hop.setdefault(("destination", label), t)
    complete = all(("source", p) in hop for p in SOURCE_POINTS) and all(
        ("destination", p) in hop for p in DEST_POINTS
    )
    return hop if complete else None


def _dest_label(point: str, later: list[tuple[float, str]]) -> str | None:
    """The label of a destination point (one of :data:`DEST_POINTS`), or None. Frame points
    carry their request (``frame_read(transfer)``, ``replied(commit)``; ``frame_arrived``
    takes the request of the next frame read); those of other requests, and the points the
    same process stamps as the next hop's source, are left out."""
    if point == "frame_arrived":
        kind = next(
            (p[len("frame_read(") : -1] for _, p in later if p.startswith("frame_read(")), None
        )
        label = f"frame_arrived ({kind})"
    else:
        label = point
        for name in ("frame_read", "replied"):
            if point.startswith(name + "("):
                label = f"{name} ({point[len(name) + 1 : -1]})"
    return label if label in DEST_POINTS else None


@dataclass
class TimelineRun:
    """A probed run: its hop median and its timeline."""

    floats: int
    median_ms: float
    points: list[Point]


def measure(
    floats: int, hops: int, warmup: int = 2, payload: str = "packed", tls: str | Path | None = None
) -> TimelineRun:
    """Run the benchmark with the probes compiled in (no naive hop) and read the timeline."""
    with tempfile.TemporaryDirectory(prefix="dfrl-probe-") as folder:
        result = migrate.run(
            floats, hops, warmup, naive=False, payload=payload, tls=tls, probe_dir=folder
        )
        points = timeline(folder, warmup)
    if not points:
        raise RuntimeError("the probed run left no complete hop (were the probes compiled in?)")
    return TimelineRun(floats, result.median_ms, points)


def table(run: TimelineRun) -> str:
    """The timeline as text, one point a line."""
    lines = [
        f"  timeline of a hop with {run.floats} floats (probed run, median hop "
        f"{run.median_ms:.3f} ms): point, side, ms from move_called, step"
    ]
    for p in run.points:
        lines.append(f"    {p.point:28} {p.side:12} {p.at_ms:8.3f}  +{p.step_ms:7.3f}")
    return "\n".join(lines)
