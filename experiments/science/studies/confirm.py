"""``--confirm-seeds K`` of ``dfrl speedup`` and ``transfer-study``: a study run on the batched
simulator (the default) runs its headline contrasts again on pybullet, the reference
simulator, with its first K seeds, and says for each whether the two agree.

The headline contrasts, read off each report:

* ``speedup`` (:mod:`.speedup_report`): T(1)/T(N) at the largest N, in the homogeneous
  condition (the theory's setting; the first condition when it was not run), one contrast per
  measure (each error target and the score), with its two verdicts (linear speed-up, any
  speed-up). Pybullet runs only N = 1 and that N in that condition.
* ``transfer-study`` (:mod:`..transfer.claims`): the primary claims, federated minus each
  control (the five standalone sources and zeros) on collisions and on the score while
  learning, which the report's headline counts. Pybullet runs those sources (no ``extra``
  ones) with the arenas' thresholds of the batched study before their lift: the time to the
  threshold, a secondary claim, is not confirmed, so no reference runs are needed.

Each side keeps its own analysis: the batched estimate, interval and verdict are the study's
(Holm over the whole study), the pybullet ones those of the same analysis on the confirmation's
runs (Holm over its own claims). A contrast **agrees** when the pybullet 95% interval contains
the batched estimate or both verdicts are the same (:attr:`Confirmation.agrees`; a ratio whose
estimate is unknown, both medians beyond the budget, is contained only by another unknown):
with few pybullet seeds the verdicts often differ by power alone (not significant against holds
or refuted; below 3 seeds always cannot judge), the interval rule then decides.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

from dfrl.experiments.science.reference import Reference
from dfrl.experiments.science.studies.simulators import BATCHED, PYBULLET
from dfrl.experiments.science.studies.speedup import SpeedupOptions, measures, run_all
from dfrl.experiments.science.studies.speedup_report import SpeedupRow, analyse, verdict
from dfrl.experiments.science.transfer.claims import PRIMARY, Claim, cell_text, claims
from dfrl.experiments.science.transfer.study import StudyOptions, transfer_study

#: The ``--confirm-seeds`` the help suggests: enough for a verdict (3 seeds at least) at a
#: pybullet cost of minutes.
SUGGESTED_SEEDS = {"speedup": 5, "transfer-study": 10}
#: The rule of :attr:`Confirmation.agrees`, in the report's words.
RULE = (
    "agrees: the pybullet 95% interval contains the batched estimate, or both verdicts are the same"
)


@dataclass(frozen=True)
class Estimate:
    """One simulator's estimate of a contrast: the value, its 95% interval, the seeds it was
    measured on, the verdict in the report's words and the outcome of each claim on it
    (``claims``: their names, e.g. ``linear`` and ``any`` speed-up)."""

    estimate: float
    low: float
    high: float
    n: int
    verdict: str
    outcomes: tuple[str, ...]
    claims: tuple[str, ...] = ("claim",)

    def brief(self) -> str:
        """The outcomes in a few words (``linear refuted; any holds``; one claim: its
        outcome)."""
        if len(self.outcomes) == 1:
            return self.outcomes[0]
        return "; ".join(f"{c} {o}" for c, o in zip(self.claims, self.outcomes))

    def to_dict(self) -> dict[str, Any]:
        return {
            "estimate": _finite(self.estimate),
            "low": _finite(self.low),
            "high": _finite(self.high),
            "n": self.n,
            "verdict": self.verdict,
            "outcomes": dict(zip(self.claims, self.outcomes)),
        }


@dataclass(frozen=True)
class Confirmation:
    """A headline contrast on both simulators."""

    contrast: str
    batched: Estimate
    pybullet: Estimate

    @property
    def contains(self) -> bool:
        """The pybullet interval contains the batched estimate; an estimate that is NaN (a
        ratio of two medians beyond the budget: unknown) only another NaN."""
        if math.isnan(self.batched.estimate):
            return math.isnan(self.pybullet.estimate)
        return self.pybullet.low <= self.batched.estimate <= self.pybullet.high

    @property
    def same_verdict(self) -> bool:
        return self.batched.outcomes == self.pybullet.outcomes

    @property
    def agrees(self) -> bool:
        """:data:`RULE`."""
        return self.contains or self.same_verdict

    def to_dict(self) -> dict[str, Any]:
        return {
            "contrast": self.contrast,
            "batched": self.batched.to_dict(),
            "pybullet": self.pybullet.to_dict(),
            "contains": self.contains,
            "same_verdict": self.same_verdict,
            "agrees": self.agrees,
            "rule": RULE,
        }


def check_confirm(sim: str, seeds: int, available: int) -> None:
    """Raises ValueError unless ``seeds`` (K) can confirm a study of ``available`` seeds run
    on ``sim``: 0 (off), or 1..available on the batched simulator."""
    if seeds < 0:
        raise ValueError(f"--confirm-seeds must be >= 0, got {seeds}")
    if seeds and sim != BATCHED:
        raise ValueError(
            f"--confirm-seeds confirms a study of the {BATCHED} simulator on "
            f"{PYBULLET}; this one runs on {sim}"
        )
    if seeds > available:
        raise ValueError(f"--confirm-seeds {seeds}: the study has only {available} seeds")


def disagreeing(found: Sequence[Confirmation]) -> list[Confirmation]:
    """The contrasts whose two simulators do not agree."""
    return [c for c in found if not c.agrees]


# -- speedup ---------------------------------------------------------------------------------
def speedup_condition(opts: SpeedupOptions) -> str:
    """The condition of the speed-up headline: homogeneous, else the first one run."""
    return "homogeneous" if "homogeneous" in opts.conditions else opts.conditions[0]


def _speedup_estimate(row: SpeedupRow) -> Estimate:
    if row.ratio is None or row.linear is None or row.faster is None:
        raise ValueError(f"N = {row.robots} has no ratio (the baseline)")
    words = (
        f"linear: {verdict(row.linear, 'linear speed-up')}; any: {verdict(row.faster, 'speed-up')}"
    )
    return Estimate(
        row.ratio.estimate,
        row.ratio.low,
        row.ratio.high,
        row.runs,
        words,
        (row.linear.outcome.value, row.faster.outcome.value),
        ("linear", "any"),
    )


def confirm_speedup(
    opts: SpeedupOptions,
    rows: Sequence[SpeedupRow],
    reference: Reference,
    seeds: int,
    progress: Callable[[int, int, dict[str, Any]], None] | None = None,
) -> list[Confirmation]:
    """T(1)/T(N) at the largest N of the headline condition on pybullet with the first
    ``seeds`` seeds of ``opts`` (the batched study's :func:`.speedup_report.analyse` rows
    ``rows``), one :class:`Confirmation` per measure. Nothing is recorded to a runs file.

    Raises
    ------
    ValueError
        :func:`check_confirm` refuses ``seeds``, or the study has no N > 1.
    """
    check_confirm(opts.sim, seeds, len(opts.seeds))
    n, cond = max(opts.robots), speedup_condition(opts)
    if n == 1:
        raise ValueError("--confirm-seeds: the study has no N > 1 to confirm T(1)/T(N) at")
    sub = replace(opts, robots=(1, n), seeds=opts.seeds[:seeds], conditions=(cond,), sim=PYBULLET)
    again = {
        (r.measure, r.robots): r
        for r in analyse(sub, run_all(sub, reference, progress))
        if r.condition == cond
    }
    first = {r.measure: r for r in rows if r.condition == cond and r.robots == n}
    return [
        Confirmation(
            f"{cond} T(1)/T({n}), {m}",
            _speedup_estimate(first[m]),
            _speedup_estimate(again[(m, n)]),
        )
        for m in measures(opts)
    ]


# -- transfer-study --------------------------------------------------------------------------
def _claim_estimate(c: Claim) -> Estimate:
    e = c.estimate
    return Estimate(
        float(e.mean),
        float(e.low),
        float(e.high),
        int(e.n),
        c.words(),
        (c.judgement.outcome.value,),
    )


def confirmation_options(
    opts: StudyOptions, rows: Sequence[dict[str, Any]], seeds: int
) -> StudyOptions:
    """The pybullet study of the confirmation: the first ``seeds`` source seeds, no extra
    controls, each arena's threshold that of the batched ``rows`` before its lift."""
    given = {r["arena"]: float(r["threshold_base"]) for r in rows}
    return replace(
        opts,
        source_seeds=opts.source_seeds[:seeds],
        extra=(),
        sim=PYBULLET,
        threshold=None,
        arena_thresholds=tuple(given.items()),
    )


def confirm_transfer(
    opts: StudyOptions,
    rows: Sequence[dict[str, Any]],
    found: Sequence[Claim],
    seeds: int,
    resamples: int = 4000,
    progress: Callable[[str], None] | None = None,
) -> list[Confirmation]:
    """The primary claims of the batched study (``rows``, judged as ``found``) against the
    federated source's standalone and zeros controls, again on pybullet
    (:func:`confirmation_options`), one :class:`Confirmation` per claim.

    Raises
    ------
    ValueError
        :func:`check_confirm` refuses ``seeds``.
    """
    check_confirm(opts.sim, seeds, len(opts.source_seeds))
    sub = confirmation_options(opts, rows, seeds)
    again = {
        (c.measure, c.control): c for c in claims(transfer_study(sub, progress), sub, resamples)
    }
    return [
        Confirmation(
            f"{c.measure}: {opts.federated} - {c.control}",
            _claim_estimate(c),
            _claim_estimate(again[(c.measure, c.control)]),
        )
        for c in found
        if c.measure in PRIMARY and (c.measure, c.control) in again
    ]


# -- report ----------------------------------------------------------------------------------
def _finite(x: float) -> float | str:
    return x if math.isfinite(x) else str(x)


def _shown(e: Estimate) -> str:
    return f"{cell_text(e.estimate)} [{cell_text(e.low)}, {cell_text(e.high)}] (n = {e.n})"


def markdown(found: Sequence[Confirmation], design: str, wall_s: float, heading: str = "##") -> str:
    """The report's "Confirmation in pybullet" section: ``design`` (what ran), the rule, the
    disagreements first, then one line per contrast."""
    off = disagreeing(found)
    said = (
        f"**{len(off)} of {len(found)} contrasts disagree**: {'; '.join(c.contrast for c in off)}."
        if off
        else f"{len(found)} of {len(found)} contrasts agree."
    )
    L = [
        f"{heading} Confirmation in pybullet",
        "",
        f"{design} Wall time {wall_s:.0f} s. Each side's own analysis (its intervals, its "
        f"Holm family); {RULE}. {said}",
        "",
        "| contrast | batched [95%] | batched verdict | pybullet [95%] | pybullet verdict "
        "| agrees |",
        "|---|---|---|---|---|---|",
    ]
    for c in found:
        L.append(
            f"| {c.contrast} | {_shown(c.batched)} | {c.batched.brief()} | "
            f"{_shown(c.pybullet)} | {c.pybullet.brief()} | "
            f"{'yes' if c.agrees else '**no**'} |"
        )
    return "\n".join(L)


def speedup_design(opts: SpeedupOptions, seeds: int) -> str:
    """The speed-up confirmation in a sentence."""
    return (
        f"T(1)/T({max(opts.robots)}) in the {speedup_condition(opts)} condition, the "
        f"headline, again on pybullet with seeds {', '.join(map(str, opts.seeds[:seeds]))} "
        f"(N = 1 and {max(opts.robots)} only, the study's other options)."
    )


def transfer_design(opts: StudyOptions, seeds: int) -> str:
    """The transfer confirmation in a sentence."""
    return (
        f"The primary claims ({' and '.join(PRIMARY)}, {opts.federated} minus each "
        f"control), the headline, again on pybullet with source seeds "
        f"{', '.join(map(str, opts.source_seeds[:seeds]))} (no extra controls; each "
        f"arena's threshold the batched one before its lift: the time to it is not "
        f"confirmed)."
    )
