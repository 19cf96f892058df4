"""``evaluations.csv``: every greedy evaluation of a study, one row each, the data its questions
are judged from (``dfrl paper`` writes it; ``dfrl paper --from DIR`` reads it back).

Columns (:data:`COLUMNS`):

=================== ===========================================================================
``run``             the condition's name: ``qlearning/average``, ``standalone/sarsa``,
                    ``control/qlearning/average``, ``untrained`` (:mod:`.catalogue` lists them)
``seed``            the study seed (int); conditions of one seed share their training seeds'
                    base and their evaluation episodes
``robot``           the robot (the untrained table: one robot per arena, named by the arena)
``robot_arena``     the arena the robot learnt in
``iteration``       the robot's iteration when its table was taken (int)
``arena``           where the table was evaluated
``role``            ``own`` (``arena`` is ``robot_arena``) or ``held_out`` (never learnt in)
``score``           the greedy score (progress - 0.05 x collisions per 1,000 steps)
``collisions_per_1000``, ``progress``   its two parts
=================== ===========================================================================

A condition's measure for a seed is taken at each robot's last evaluated iteration.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: The file name in a study's folder.
EVALUATIONS_FILE = "evaluations.csv"
COLUMNS = (
    "run",
    "seed",
    "robot",
    "robot_arena",
    "iteration",
    "arena",
    "role",
    "score",
    "collisions_per_1000",
    "progress",
)
ROLES = ("own", "held_out")
MEASURES = ("score", "collisions_per_1000", "progress")


class EvaluationsError(ValueError):
    """A row of ``evaluations.csv`` that cannot be read; the message names file and line."""


@dataclass(frozen=True)
class Evaluation:
    """One greedy evaluation of one table in one arena."""

    run: str
    seed: int
    robot: str
    robot_arena: str
    iteration: int
    arena: str
    role: str
    score: float
    collisions_per_1000: float
    progress: float

    def row(self) -> tuple[Any, ...]:
        return tuple(getattr(self, c) for c in COLUMNS)


def write_evaluations(path: str | Path, rows: Iterable[Evaluation]) -> int:
    """Write ``rows`` sorted by run, seed, robot, iteration, arena; return how many."""
    ordered = sorted(rows, key=lambda e: (e.run, e.seed, e.robot, e.iteration, e.arena))
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(COLUMNS)
        for e in ordered:
            w.writerow(e.row())
    return len(ordered)


def read_evaluations(path: str | Path) -> list[Evaluation]:
    """Every row of an ``evaluations.csv``.

    Raises
    ------
    EvaluationsError
        No row, a missing column, a value that is not a number where one is needed, an
        unknown role, an own row whose arena is not the robot's, or a non-finite measure: the
        file and line.
    OSError
        The file cannot be read.
    """
    path = Path(path)
    out = []
    with open(path, newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(fh)
        missing = [c for c in COLUMNS if c not in (reader.fieldnames or [])]
        if missing:
            raise EvaluationsError(
                f"{path}:1: missing column(s) {', '.join(missing)}; expected {', '.join(COLUMNS)}"
            )
        for line, rec in enumerate(reader, start=2):
            out.append(_parse(rec, f"{path}:{line}"))
    if not out:
        raise EvaluationsError(f"{path}:2: no evaluation rows: nothing to judge")
    return out


def _parse(rec: Mapping[str, str], where: str) -> Evaluation:
    def number(col: str, kind: type) -> Any:
        text = (rec.get(col) or "").strip()
        try:
            value = kind(text) if kind is int else float(text)
        except ValueError:
            what = "an integer" if kind is int else "a number"
            raise EvaluationsError(f"{where}: {col} must be {what}, got {text!r}") from None
        if kind is float and not math.isfinite(value):
            raise EvaluationsError(f"{where}: {col} is not finite ({text})")
        return value

    texts = {
        c: (rec.get(c) or "").strip() for c in ("run", "robot", "robot_arena", "arena", "role")
    }
    for c, v in texts.items():
        if not v:
            raise EvaluationsError(f"{where}: {c} is empty")
    if texts["role"] not in ROLES:
        raise EvaluationsError(
            f"{where}: role must be one of {', '.join(ROLES)}, got {texts['role']!r}"
        )
    if texts["role"] == "own" and texts["arena"] != texts["robot_arena"]:
        raise EvaluationsError(
            f"{where}: an own evaluation in {texts['arena']!r} of a robot of "
            f"{texts['robot_arena']!r}"
        )
    return Evaluation(
        texts["run"],
        number("seed", int),
        texts["robot"],
        texts["robot_arena"],
        number("iteration", int),
        texts["arena"],
        texts["role"],
        number("score", float),
        number("collisions_per_1000", float),
        number("progress", float),
    )


def from_rows(
    run: str, seed: int, rows: Iterable[Mapping[str, Any]], arenas: Mapping[str, str] | None = None
) -> list[Evaluation]:
    """Evaluations from the per-run ``evaluations.csv`` rows of the studies (``robot,
    iteration, arena, role, score, ...``); ``arenas`` maps robot -> its arena (default: the
    arena of its ``own`` rows)."""
    rows = list(rows)
    own = {str(r["robot"]): str(r["arena"]) for r in rows if r["role"] == "own"}
    if arenas:
        own.update(arenas)
    return [
        Evaluation(
            run,
            int(seed),
            str(r["robot"]),
            own.get(str(r["robot"]), "?"),
            int(r["iteration"]),
            str(r["arena"]),
            str(r["role"]),
            float(r["score"]),
            float(r["collisions_per_1000"]),
            float(r["progress"]),
        )
        for r in rows
    ]
