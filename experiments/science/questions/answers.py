"""Judge every question of a study from its evaluations: :func:`answer`.

Order of work: the checks first (each learning control minus the untrained table, 95% t
interval, no correction: a check that errs, errs towards failing the control); then each
question's family, Holm within it; an L row of a condition whose control failed its check, or
which has no control, is "cannot judge" with the reason and takes no part in the correction.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

from dfrl.experiments.science.questions.catalogue import CONTROL, DELTAS, UNTRAINED, Row, rows_for
from dfrl.experiments.science.questions.contrast import Contrast, Judged, Outcome, judge_family
from dfrl.experiments.science.questions.evaluations import Evaluation
from dfrl.experiments.science.questions.measures import ByArena, final_by_arena, paired, runs_of


@dataclass(frozen=True)
class Answered:
    """A row, its judged contrast and the same contrast on collisions per 1,000 steps."""

    row: Row
    judged: Judged
    collisions: Contrast


@dataclass(frozen=True)
class CheckResult:
    """A learning control minus the untrained table: does its interval include 0?"""

    row: Row
    contrast: Contrast

    @property
    def passes(self) -> bool:
        low, high = self.contrast.interval()
        return self.contrast.n >= 3 and not self.contrast.degenerate and low <= 0 <= high

    @property
    def vetoes(self) -> bool:
        """Whether L cannot use this control: it cannot be checked, or it fails and its
        interval reaches delta (a control that learns less than delta but not nothing is
        shown as failing, and L's rows are still judged: trained minus control removes it)."""
        c = self.contrast
        if c.n < 3 or c.degenerate:
            return True
        low, high = c.interval()
        return not self.passes and max(abs(low), abs(high)) >= c.delta

    def words(self) -> str:
        c = self.contrast
        if c.n < 3 or c.degenerate:
            return f"cannot check (n = {c.n}{', no spread' if c.n >= 2 else ''})"
        low, high = c.interval()
        if self.passes:
            return "includes 0: learns nothing we can detect"
        return f"FAILS: the control learns ({c.estimate:+.3f} [{low:+.3f}, {high:+.3f}])" + (
            "" if self.vetoes else f", less than delta = {c.delta:g}: L is still judged against it"
        )


@dataclass
class Answers:
    """Every question's rows, the checks, the deltas used and the per-arena values."""

    deltas: dict[str, float]
    checks: list[CheckResult] = field(default_factory=list)
    questions: dict[str, list[Answered]] = field(default_factory=dict)
    values: ByArena = field(default_factory=dict)

    def learns(self) -> dict[str, str]:
        """L's answer per trained condition: ``holds`` when both its rows hold, ``cannot
        judge`` when either cannot be judged, else the verdict of the weaker row."""
        out: dict[str, list[Answered]] = {}
        for a in self.questions.get("L", []):
            out.setdefault(a.row.a, []).append(a)
        answer = {}
        for run, rows in out.items():
            outcomes = [a.judged.outcome for a in rows]
            if all(o is Outcome.HOLDS for o in outcomes):
                answer[run] = "holds"
            else:
                worst = next(a for a in rows if a.judged.outcome is not Outcome.HOLDS)
                answer[run] = worst.judged.words()
        return answer


def _contrast(values: ByArena, row: Row, measure: str, delta: float) -> Contrast:
    seeds, a, b = paired(values, row.a, row.b, row.role, measure)
    return Contrast(tuple(seeds), tuple(a), tuple(b), row.side, delta)


def answer(evals: Iterable[Evaluation], deltas: Mapping[str, float] | None = None) -> Answers:
    """Judge the checks and the questions L, F, T, M on ``evals``.

    ``deltas``: question -> smallest effect of interest (:data:`.catalogue.DELTAS` for those
    not given); the checks use L's.
    """
    d = {**DELTAS, **(deltas or {})}
    values = final_by_arena(evals)
    runs = runs_of(values)
    rows = rows_for(runs)
    out = Answers(deltas=d, values=values)
    for row in rows["C"]:
        out.checks.append(CheckResult(row, _contrast(values, row, "score", d["L"])))
    failed = {c.row.a: c.words() for c in out.checks if c.vetoes}
    for q in ("L", "F", "T", "M"):
        family = rows[q]
        contrasts = [_contrast(values, r, "score", d[q]) for r in family]
        vetoes = [_veto(r, runs, failed) for r in family] if q == "L" else None
        judged = judge_family(contrasts, vetoes)
        out.questions[q] = [
            Answered(r, j, _contrast(values, r, "collisions_per_1000", d[q]))
            for r, j in zip(family, judged)
        ]
    return out


def _veto(row: Row, runs: list[str], failed: Mapping[str, str]) -> str:
    """Why an L row cannot be judged ('' when it can)."""
    control = CONTROL + row.a
    if UNTRAINED not in runs:
        return "no untrained table in the study"
    if control not in runs:
        return f"no learning control ({control}) in the study"
    if control in failed:
        return f"its control {control}: {failed[control]}"
    return ""
