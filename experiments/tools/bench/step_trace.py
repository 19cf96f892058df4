"""The step traces the benchmarks write (``step_trace.pl``): reading them, and summing up the
steps of a traced round.

A traced process writes ``DIR/ROLE.jsonl``, one JSON object a line: ``step`` (the traced
predicate's step name), ``t0`` and ``t1`` (its call's start and end, seconds since the epoch)
and ``thread``. The robot processes of ``dfrl bench round --trace DIR`` are ``robot-<id>``.
"""

from __future__ import annotations

import json
import statistics
from dataclasses import dataclass
from pathlib import Path

ENV = "DFRL_STEP_TRACE"
"""The environment variable that makes a process trace (its value: the folder)."""

PROLOG_FILE = Path(__file__).with_name("step_trace.pl")
"""The Prolog side: wraps the platform's predicates and writes the records."""


@dataclass(frozen=True)
class StepRecord:
    t0: float
    t1: float
    step: str
    role: str


@dataclass(frozen=True)
class StepSummary:
    step: str
    calls: int
    median_ms: float
    p90_ms: float
    total_ms: float
    """Summed over every call in every traced process (calls nest: ``step`` holds
    ``bridge_call``)."""


def read_steps(trace_dir: str | Path, roles: list[str] | None = None) -> list[StepRecord]:
    """Every step recorded in ``trace_dir`` (only the files of ``roles`` if given), in the
    order of their start."""
    folder = Path(trace_dir)
    paths = (
        [folder / f"{r}.jsonl" for r in roles]
        if roles is not None
        else sorted(folder.glob("*.jsonl"))
    )
    records: list[StepRecord] = []
    for path in paths:
        if path.exists():
            for line in path.read_text().splitlines():
                d = json.loads(line)
                records.append(StepRecord(d["t0"], d["t1"], d["step"], path.stem))
    records.sort(key=lambda r: (r.t0, r.t1))
    return records


def step_summary(trace_dir: str | Path) -> list[StepSummary]:
    """Each step's count and durations over all the files in ``trace_dir``, the largest
    total first."""
    per: dict[str, list[float]] = {}
    for r in read_steps(trace_dir):
        per.setdefault(r.step, []).append((r.t1 - r.t0) * 1000)
    out = [
        StepSummary(
            step,
            len(ms),
            statistics.median(ms),
            sorted(ms)[min(len(ms) - 1, int(0.9 * len(ms)))],
            sum(ms),
        )
        for step, ms in per.items()
    ]
    return sorted(out, key=lambda s: -s.total_ms)
