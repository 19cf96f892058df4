"""The transfer study's claims, intervals and verdicts, and its files.

Unit of analysis: the source seed. A source's value of a measure is the mean over its
learning phases (unseen arenas x target seeds). Each claim compares the federated source with
one control (a standalone source of each source arena, and ``zeros``). Two families:

* **primary** (:data:`PRIMARY`), Holm's correction over their claims together:
  **collisions while learning**, federated minus control, claimed below 0; the **score while
  learning** (the mean greedy score over the phase, the area under its curve), federated minus
  control, claimed above 0. Paired t interval of the per-seed differences when both were
  trained with the same seeds (the controls are matched: standalone robot k has federated
  robot k's training seed, and the learning phases of a source seed share their seeds), Welch's
  otherwise.
* **secondary**, Holm over its own claims: the **time to the threshold** (each arena's own,
  lifted above every phase's iteration-0 score), claimed shorter. When no learning phase of
  either side is censored: federated minus control in iterations, paired or Welch as above.
  When any is: the difference of Kaplan-Meier medians federated - control over the learning
  phases; the censored phases are counted. Matched sources:
  :func:`paired_censored_difference`, the source seeds resampled, each drawn seed bringing its
  phases of both sides (the pairing kept); otherwise :func:`censored_difference`, each side's
  phases resampled on their own.

Every claim is judged with :func:`~dfrl.experiments.science.statistics.judge`, except that an
interval that cannot carry a verdict is **cannot judge** with the reason
(:func:`degenerate`): zero width (the difference is the same in every seed, or every resample
gives one value) or every resample giving the same difference; such a claim has no p-value and
takes no place in its Holm family (:func:`~dfrl.experiments.science.statistics.adjust`).
The smallest detectable effect D of a t interval is ``(t(0.975, df) + t(0.8, df)) x se``; of
a censored difference ``(z(0.975) + z(0.8)) x se``, se = the interval's width / (2 x 1.96)
(``inf`` for an open interval).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from dfrl.experiments.science.censored import km_median
from dfrl.experiments.science.statistics import (
    LEVEL,
    POWER,
    Interval,
    Judgement,
    Outcome,
    adjust,
    interval,
    judge,
    normal_quantile,
    paired,
    welch,
)
from dfrl.experiments.science.tidy import TIDY_FILE, Row, write_tidy
from dfrl.experiments.science.transfer.model import json_safe
from dfrl.experiments.science.transfer.study import StudyOptions

MEASURES = ("collisions_per_1000", "score_auc", "time_to_threshold")
#: The measures of the primary family (Holm over their claims together); the others are
#: secondary (Holm over their own).
PRIMARY = ("collisions_per_1000", "score_auc")
#: The side of 0 the claim puts federated minus control on.
SIDE = {"collisions_per_1000": "below", "score_auc": "above", "time_to_threshold": "below"}
#: Each measure in the report's words.
WORDS = {
    "collisions_per_1000": "collisions while learning",
    "score_auc": "score while learning",
    "time_to_threshold": "time to the threshold",
}
#: Fewest source seeds a claim is judged on.
MIN_SEEDS = 3


def per_seed(rows: Sequence[dict[str, Any]], condition: str, measure: str) -> dict[int, float]:
    """pair seed -> the mean of ``measure`` over that source's learning phases."""
    mine = [r for r in rows if r["condition"] == condition]
    seeds = sorted({r["pair_seed"] for r in mine})
    return {
        s: float(np.mean([float(r[measure]) for r in mine if r["pair_seed"] == s])) for s in seeds
    }


def compare(a: dict[int, float], b: dict[int, float]) -> tuple[Interval, str]:
    """``a - b`` with its 95% interval: paired t when both have values for the same seeds
    (``"paired"``), Welch's otherwise (``"Welch"``)."""
    if set(a) == set(b):
        keys = sorted(a)
        return paired([a[k] for k in keys], [b[k] for k in keys]), "paired"
    return welch(list(a.values()), list(b.values())), "Welch"


@dataclass(frozen=True)
class CensoredDifference:
    """``median_a - median_b`` of Kaplan-Meier medians of censored times, with its 95%
    percentile bootstrap interval; a median beyond the budget is known only to exceed the
    group's largest time, so each resample gives the lowest and highest difference it allows
    (``low`` from the lowest, ``high`` from the highest: a censored median never counts for a
    claim). ``known``: ``exact``, ``at least`` (a's beyond), ``at most`` (b's), ``unknown``.
    Has what :func:`judge` needs of an interval."""

    estimate: float
    low: float
    high: float
    n: int
    known: str
    draws: np.ndarray = field(repr=False, compare=False)

    @property
    def mean(self) -> float:
        return self.estimate

    @property
    def half(self) -> float:
        return (self.high - self.low) / 2.0

    def p_value(self, null: float = 0.0) -> float:
        """Twice the smaller share of resamples that allow a difference on one side of
        ``null``, at most 1."""
        below, above = np.mean(self.draws[:, 0] <= null), np.mean(self.draws[:, 1] >= null)
        return float(min(1.0, 2.0 * min(below, above)))

    def detectable(self, power: float = POWER) -> float:
        if not (math.isfinite(self.low) and math.isfinite(self.high)):
            return math.inf
        z = normal_quantile(0.5 + LEVEL / 2.0)
        return (z + normal_quantile(power)) * (self.high - self.low) / (2.0 * z)

    def __str__(self) -> str:
        sign = {"at least": ">= ", "at most": "<= "}.get(self.known, "")
        return f"{sign}{cell_text(self.estimate)} [{cell_text(self.low)}, {cell_text(self.high)}]"


def _median_bounds(t: np.ndarray, ok: np.ndarray) -> tuple[float, float]:
    m = km_median(t.tolist(), ok.tolist())
    return (m, m) if math.isfinite(m) else (float(t.max()), math.inf)


def _difference(
    ta: np.ndarray, ea: np.ndarray, tb: np.ndarray, eb: np.ndarray, n: int, draws: np.ndarray
) -> CensoredDifference:
    """The estimate of the whole samples and the interval of ``draws`` (lowest and highest
    difference each resample allows)."""
    (al, ah), (bl, bh) = _median_bounds(ta, ea), _median_bounds(tb, eb)
    known = {
        (True, True): "exact",
        (False, True): "at least",
        (True, False): "at most",
        (False, False): "unknown",
    }[(al == ah, bl == bh)]
    est = {"exact": al - bl, "at least": al - bl, "at most": ah - bl}.get(known, math.nan)
    tail = (1.0 - LEVEL) / 2.0
    return CensoredDifference(
        float(est),
        float(np.quantile(draws[:, 0], tail, method="lower")),
        float(np.quantile(draws[:, 1], 1.0 - tail, method="higher")),
        n,
        known,
        draws,
    )


def _draw(ta: np.ndarray, ea: np.ndarray, tb: np.ndarray, eb: np.ndarray) -> tuple[float, float]:
    (xl, xh), (yl, yh) = _median_bounds(ta, ea), _median_bounds(tb, eb)
    return xl - yh, xh - yl


def censored_difference(
    a: tuple[Sequence[float], Sequence[bool]],
    b: tuple[Sequence[float], Sequence[bool]],
    n: int,
    resamples: int = 4000,
    seed: int = 0,
) -> CensoredDifference:
    """Kaplan-Meier median of ``a`` minus that of ``b`` (``(times, reached)`` each, reached
    False: censored at that time), each group resampled with replacement on its own from a
    generator seeded with ``seed``; ``n`` is the count the verdict is given at."""
    ta, ea = np.asarray(a[0], dtype=float), np.asarray(a[1], dtype=bool)
    tb, eb = np.asarray(b[0], dtype=float), np.asarray(b[1], dtype=bool)
    rng = np.random.default_rng(seed)
    draws = np.empty((resamples, 2))
    for k in range(resamples):
        i, j = rng.integers(0, len(ta), len(ta)), rng.integers(0, len(tb), len(tb))
        draws[k] = _draw(ta[i], ea[i], tb[j], eb[j])
    return _difference(ta, ea, tb, eb, n, draws)


Phases = tuple[Sequence[float], Sequence[bool]]


def paired_censored_difference(
    a: Sequence[Phases], b: Sequence[Phases], resamples: int = 4000, seed: int = 0
) -> CensoredDifference:
    """As :func:`censored_difference` for matched sources: ``a[i]`` and ``b[i]`` are the
    learning phases (times, reached) of source seed i under the two conditions. Each resample
    draws n seeds with replacement (n = ``len(a)``, the count the verdict is given at) and
    pools the phases of the drawn seeds on both sides, so a seed whose phases are slow on one
    side brings its slow phases on the other too.

    Raises
    ------
    ValueError
        ``a`` and ``b`` have not the same number of seeds, or a seed has no phase.
    """
    if len(a) != len(b) or not a or any(len(x[0]) == 0 for x in list(a) + list(b)):
        raise ValueError(
            f"paired censored times need the same seeds on both sides, each with "
            f"phases: {len(a)} and {len(b)} seeds"
        )
    sa = [(np.asarray(t, dtype=float), np.asarray(r, dtype=bool)) for t, r in a]
    sb = [(np.asarray(t, dtype=float), np.asarray(r, dtype=bool)) for t, r in b]

    def pool(
        groups: list[tuple[np.ndarray, np.ndarray]], idx: Sequence[int] | np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        return (
            np.concatenate([groups[i][0] for i in idx]),
            np.concatenate([groups[i][1] for i in idx]),
        )

    rng = np.random.default_rng(seed)
    draws = np.empty((resamples, 2))
    for k in range(resamples):
        idx = rng.integers(0, len(sa), len(sa))
        draws[k] = _draw(*pool(sa, idx), *pool(sb, idx))
    everything = range(len(sa))
    return _difference(*pool(sa, everything), *pool(sb, everything), len(sa), draws)


def degenerate(estimate: Interval | CensoredDifference) -> str | None:
    """Why an interval cannot carry a verdict, or None when it can: zero width (a t interval
    of differences that are the same in every seed, a bootstrap interval whose ends meet) or
    a bootstrap whose every resample gives the same difference (its ends then say nothing of
    the spread between seeds: its p-value would be 0 or 1 by construction), or one open at
    both ends (-inf, inf: it excludes nothing, its p-value is 1 by construction)."""
    if isinstance(estimate, CensoredDifference):
        d = estimate.draws
        if len(d) and bool((d == d[0]).all()):
            lo, hi = float(d[0, 0]), float(d[0, 1])
            said = cell_text(lo) if lo == hi else f"[{cell_text(lo)}, {cell_text(hi)}]"
            return f"every resample gives the same difference, {said}"
        if estimate.low == estimate.high:
            return f"zero width: every resample's difference is {cell_text(estimate.low)}"
        if math.isinf(estimate.low) and math.isinf(estimate.high):
            return (
                "open at both ends: in most resamples a source never reached the "
                "threshold, the difference is unbounded"
            )
        return None
    if estimate.half == 0.0:
        return f"zero width: the difference is {cell_text(estimate.mean)} in every seed"
    return None


def verdict(estimate: Interval | CensoredDifference, side: str) -> tuple[Judgement, str]:
    """The (unadjusted) verdict on "federated minus control is ``side`` 0" and, for cannot
    judge, its reason: :func:`judge` with at least :data:`MIN_SEEDS` seeds, else cannot
    judge; a :func:`degenerate` interval is cannot judge too. A claim that cannot be judged
    has no p-value (NaN), so that Holm's correction leaves it out of the family."""
    j = judge(estimate, 0.0, side, MIN_SEEDS)
    if estimate.n < MIN_SEEDS:
        reason = f"n = {estimate.n} < {MIN_SEEDS}"
    else:
        reason = degenerate(estimate) or ""
        if not reason and j.outcome is Outcome.CANNOT_JUDGE:
            reason = f"no interval: {estimate}"
    if reason:
        j = replace(j, outcome=Outcome.CANNOT_JUDGE, p=math.nan, p_adjusted=math.nan)
    return j, reason


@dataclass(frozen=True)
class Claim:
    """One comparison of the federated source with a control on one measure."""

    measure: str
    control: str
    estimate: Interval | CensoredDifference
    method: str  #: "paired", "Welch", "censored, paired (KM medians)" or
    #: "censored (KM medians)" (unpaired)
    censored: tuple[int, int]  #: censored learning phases (federated, control)
    phases: tuple[int, int]  #: learning phases (federated, control)
    judgement: Judgement
    reason: str = ""  #: why it cannot be judged ("" otherwise)

    @property
    def family(self) -> str:
        """``primary`` or ``secondary`` (the Holm family it is adjusted in)."""
        return "primary" if self.measure in PRIMARY else "secondary"

    def words(self) -> str:
        """The verdict in the report's words (cannot judge with its reason)."""
        if self.judgement.outcome is Outcome.CANNOT_JUDGE:
            return f"cannot judge ({self.reason})"
        return self.judgement.words()

    def statement(self, federated: str) -> str:
        if self.measure == "collisions_per_1000":
            return f"{federated} collides less while learning than {self.control}"
        if self.measure == "score_auc":
            return f"{federated} scores higher while learning than {self.control}"
        return f"{federated} reaches the threshold sooner than {self.control}"

    def to_dict(self) -> dict[str, Any]:
        e = self.estimate
        return json_safe(
            {
                "measure": self.measure,
                "family": self.family,
                "control": self.control,
                "method": self.method,
                "estimate": e.mean,
                "low": e.low,
                "high": e.high,
                "n": e.n,
                "known": e.known if isinstance(e, CensoredDifference) else "exact",
                "censored": list(self.censored),
                "phases": list(self.phases),
                "bound": self.judgement.bound,
                "side": self.judgement.side,
                "p": self.judgement.p,
                "p_holm": self.judgement.p_adjusted,
                "detectable": e.detectable(),
                "verdict": self.words(),
                "reason": self.reason,
            }
        )


def _times(
    rows: Sequence[dict[str, Any]], condition: str, pair: int | None = None
) -> tuple[list[float], list[bool]]:
    """The times and reached flags of a condition's learning phases (of pair seed ``pair``
    alone when given)."""
    mine = [
        r for r in rows if r["condition"] == condition and (pair is None or r["pair_seed"] == pair)
    ]
    return [float(r["time_to_threshold"]) for r in mine], [bool(r["reached"]) for r in mine]


def claim(
    rows: Sequence[dict[str, Any]],
    federated: str,
    control: str,
    measure: str,
    resamples: int = 4000,
) -> Claim:
    """The (unadjusted) claim that ``federated`` beats ``control`` on ``measure``."""
    tf, rf = _times(rows, federated)
    tc, rc = _times(rows, control)
    censored = (rf.count(False), rc.count(False))
    phases = (len(rf), len(rc))
    est: Interval | CensoredDifference
    if measure == "time_to_threshold" and any(censored):
        fs, cs = per_seed(rows, federated, measure), per_seed(rows, control, measure)
        if set(fs) == set(cs):
            est = paired_censored_difference(
                [_times(rows, federated, s) for s in sorted(fs)],
                [_times(rows, control, s) for s in sorted(fs)],
                resamples,
            )
            how = "censored, paired (KM medians)"
        else:
            est = censored_difference((tf, rf), (tc, rc), min(len(fs), len(cs)), resamples)
            how = "censored (KM medians)"
    else:
        est, how = compare(per_seed(rows, federated, measure), per_seed(rows, control, measure))
    return Claim(measure, control, est, how, censored, phases, *verdict(est, SIDE[measure]))


def check_rows(rows: Sequence[dict[str, Any]]) -> None:
    """Refuse learning phases this version cannot judge.

    Raises
    ------
    ValueError
        No row, or rows recorded before the learning phases had seeds of their own per source
        seed and a score on the whole grid (no ``phase_seed`` or ``score_auc``): their target
        seed was shared by every source seed and their scores stopped at the threshold.
    """
    if not rows:
        raise ValueError("no learning phase")
    old = [r for r in rows if "phase_seed" not in r or "score_auc" not in r]
    if old:
        raise ValueError(
            f"{len(old)} of {len(rows)} learning phases were recorded by an "
            f"earlier version (one target seed shared by every source seed, "
            f"scores stopped at the threshold): run the study again"
        )


def claims(
    rows: Sequence[dict[str, Any]], opts: StudyOptions, resamples: int = 4000
) -> list[Claim]:
    """Every claim of the study, Holm-adjusted within its family (primary, secondary).

    Raises
    ------
    ValueError
        Rows :func:`check_rows` refuses.
    """
    check_rows(rows)
    raw = [
        claim(rows, opts.federated, c, m, resamples)
        for m in MEASURES
        for c in opts.conditions
        if c != opts.federated
    ]
    out = list(raw)
    for family in ("primary", "secondary"):
        idx = [i for i, c in enumerate(raw) if c.family == family]
        for i, j in zip(idx, adjust([raw[i].judgement for i in idx])):
            out[i] = replace(raw[i], judgement=j)
    return out


# -- report ----------------------------------------------------------------------------------
def cell_text(x: float) -> str:
    """A number as the reports show it: '-' for NaN, 'inf', thousands grouped from 1,000."""
    if math.isnan(x):
        return "-"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    return f"{x:,.0f}" if abs(x) >= 1000 else f"{x:.3g}"


def _estimate(c: Claim) -> str:
    e = c.estimate
    if isinstance(e, CensoredDifference):
        return str(e)
    return f"{cell_text(e.mean)} [{cell_text(e.low)}, {cell_text(e.high)}]"


def _level(rows: Sequence[dict[str, Any]], condition: str, measure: str) -> str:
    if not any(r["condition"] == condition for r in rows):
        return "-"
    if measure == "time_to_threshold":
        t, r = _times(rows, condition)
        med = [x for x, ok in zip(t, r) if ok]
        if len(med) < len(t):
            return f"{len(t) - len(med)} of {len(t)} censored"
    iv = interval(list(per_seed(rows, condition, measure).values()))
    if iv.half == 0.0:  # no zero-width interval: the same value in every seed
        return f"{iv.mean:.3g} in every seed (n={iv.n})"
    return str(iv)


def floor(rows: Sequence[dict[str, Any]], arena: str) -> tuple[int, int, int]:
    """The floor in ``arena``: the learning phases whose iteration-0 score is at or above
    the arena's threshold before the lift (``threshold_base``: at the threshold before they
    learnt anything), those at or above the threshold used (0 by construction) and all."""
    mine = [r for r in rows if r["arena"] == arena]
    return (
        sum(r["start_score"] >= r["threshold_base"] for r in mine),
        sum(r["start_score"] >= r["threshold"] for r in mine),
        len(mine),
    )


def markdown(
    rows: Sequence[dict[str, Any]], opts: StudyOptions, found: Sequence[Claim], wall_time: float
) -> str:
    """The study's report: the thresholds, each source's levels, then every claim with its
    verdict."""
    n = len(opts.source_seeds)
    L = [
        f"# Transfer to unseen arenas ({', '.join(opts.targets)})",
        "",
        f"Simulator: {opts.sim}. Sources: {n} source seeds, {opts.iterations} iterations "
        f"per robot (the federation "
        f"shares every {opts.respite}, method {opts.method}). Learning phase: {opts.learn} "
        f"steps from the source table in each unseen arena x {len(opts.target_seeds)} target "
        f"seed(s), seeded per source seed (the sources of a seed share the phase's seeds, no "
        f"two seeds do); greedy score ({opts.eval_steps} steps) at 0 and every "
        f"{opts.eval_every} iterations. Score while learning: its mean over the phase (area "
        f"under the score curve / {opts.learn}). Time: the first of {opts.confirm} "
        f"evaluations in a row at or above the arena's threshold, lifted above every phase's "
        f"iteration-0 score (a phase that never reaches it is censored at {opts.learn}). "
        f"Wall time {wall_time:.0f} s.",
        "",
        "| unseen arena | threshold | from | phases at the unlifted threshold at iteration 0 "
        "| at the threshold used |",
        "|---|---|---|---|---|",
    ]
    for arena, (value, origin) in thresholds_of(rows, opts).items():
        base, used, k = floor(rows, arena)
        L.append(f"| {arena} | {value:.4g} | {origin} | {base} of {k} | {used} of {k} |")
    L += [
        "",
        "| source | collisions/1000 while learning | score while learning "
        "| score at iteration 0 | time to threshold (iterations) |",
        "|---|---|---|---|---|",
    ]
    for c in opts.conditions:
        L.append(
            f"| {c} | {_level(rows, c, 'collisions_per_1000')} | "
            f"{_level(rows, c, 'score_auc')} | {_level(rows, c, 'start_score')} | "
            f"{_level(rows, c, 'time_to_threshold')} |"
        )
    fam = {
        f: sum(c.family == f and c.judgement.outcome is not Outcome.CANNOT_JUDGE for c in found)
        for f in ("primary", "secondary")
    }
    L += [
        "",
        f"Claims: {opts.federated} against each control, federated minus control. "
        "Primary: collisions while learning (claimed < 0) and score while learning (claimed "
        "> 0), paired t over source seeds (Welch when unpaired). Secondary: time to the "
        "threshold in iterations (claimed < 0), from the per-seed means when no phase is "
        "censored, else from the Kaplan-Meier medians over the learning phases (`>= x`: a "
        "bound, a median beyond the budget; matched sources: the source seeds resampled, "
        "each with its phases of both sides). 95% intervals; p adjusted by Holm within "
        f"each family ({fam['primary']} primary, {fam['secondary']} secondary claims that "
        "can be judged); an interval of zero width or whose every resample is the same "
        "cannot be judged (no p, outside the family); D = smallest detectable effect at "
        "80% power ((t(0.975, df) + t(0.8, df)) x se; censored: (z(0.975) + z(0.8)) x se, "
        "se = width / 3.92).",
        "",
        "| family | measure | control | method | estimate [95%] | censored (fed, control) "
        "| p (Holm) | verdict |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for cl in found:
        cens = (
            f"{cl.censored[0]}/{cl.phases[0]}, {cl.censored[1]}/{cl.phases[1]}"
            if cl.measure == "time_to_threshold"
            else "-"
        )
        L.append(
            f"| {cl.family} | {cl.measure} | {cl.control} | {cl.method} | {_estimate(cl)} | "
            f"{cens} | {cell_text(cl.judgement.p_adjusted)} | {cl.words()} |"
        )
    L += ["", headline(found, opts)]
    return "\n".join(L)


def thresholds_of(
    rows: Sequence[dict[str, Any]], opts: StudyOptions
) -> dict[str, tuple[float, str]]:
    """arena -> (threshold, how it was chosen) as the learning phases recorded them."""
    out: dict[str, tuple[float, str]] = {}
    for a in opts.targets:
        mine = [r for r in rows if r["arena"] == a]
        if mine:
            out[a] = (float(mine[0]["threshold"]), str(mine[0]["threshold_from"]))
    return out


def headline(found: Sequence[Claim], opts: StudyOptions) -> str:
    """One sentence per measure: against how many standalone controls the claim holds, is
    refuted, is not significant (with the range of D) or cannot be judged, and the verdict
    against ``zeros``."""
    out = []
    for m in MEASURES:
        cs = [c for c in found if c.measure == m and c.control.startswith("standalone_")]
        held = [c.control for c in cs if c.judgement.holds]
        refuted = [c.control for c in cs if c.judgement.outcome is Outcome.REFUTED]
        unsure = [c for c in cs if c.judgement.outcome is Outcome.NOT_SIGNIFICANT]
        blind = [c.control for c in cs if c.judgement.outcome is Outcome.CANNOT_JUDGE]
        s = (
            f"**{WORDS[m]}** ({'primary' if m in PRIMARY else 'secondary'}): holds against "
            f"{len(held)} of {len(cs)} standalone controls"
        )
        if refuted:
            s += f"; refuted against {', '.join(refuted)}"
        if unsure:
            ds = [c.estimate.detectable() for c in unsure]
            s += (
                f"; not significant against {len(unsure)} (D {cell_text(min(ds))}"
                + (f" to {cell_text(max(ds))}" if max(ds) != min(ds) else "")
                + ")"
            )
        if blind:
            s += f"; cannot judge against {', '.join(blind)}"
        zero = [c for c in found if c.measure == m and c.control == "zeros"]
        if zero:
            s += f"; against zeros (learning from scratch): {zero[0].words()}"
        out.append(s + ".")
    return "The paper's claim, " + " ".join(out)


# -- files -----------------------------------------------------------------------------------
def tidy_rows(rows: Sequence[dict[str, Any]]) -> Iterator[Row]:
    """``run`` = source condition, ``seed`` = source seed, ``robot`` = arena/target seed."""
    for r in rows:
        cond = r["condition"].split("_")[0]
        where = f"{r['arena']}/t{r['target_seed']}"
        run, seed, a = r["condition"], int(r["source_seed"]), r["arena"]
        for it, v in r["scores"]:
            yield (run, seed, cond, where, int(it), f"score@{a}", float(v))
        for it, v in r["collisions"]:
            yield (run, seed, cond, where, int(it), f"collisions@{a}", float(v))
        end = int(r["collisions"][-1][0])
        yield (
            run,
            seed,
            cond,
            where,
            end,
            f"collisions_per_1000_learning@{a}",
            float(r["collisions_per_1000"]),
        )
        yield (run, seed, cond, where, end, f"score_auc@{a}", float(r["score_auc"]))
        yield (run, seed, cond, where, end, f"time_to_threshold@{a}", float(r["time_to_threshold"]))
        yield (run, seed, cond, where, end, f"reached@{a}", float(bool(r["reached"])))
        yield (run, seed, cond, where, end, f"threshold@{a}", float(r["threshold"]))


def write_study(
    out: Path,
    rows: Sequence[dict[str, Any]],
    opts: StudyOptions,
    found: Sequence[Claim],
    text: str,
    wall_time: float,
    confirmation: Sequence[dict[str, Any]] | None = None,
) -> None:
    """``transfer_study.md``, ``transfer_study.json`` (options, claims, the
    ``confirmation`` in pybullet when given, rows) and ``tidy.csv`` (provenance.json is
    written when the study starts)."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "transfer_study.md").write_text(text + "\n", encoding="utf-8")
    doc = {
        "options": opts.to_dict(),
        "wall_time": round(wall_time, 3),
        "claims": [c.to_dict() for c in found],
        **({} if confirmation is None else {"confirmation": list(confirmation)}),
        "rows": json_safe(list(rows)),
    }
    (out / "transfer_study.json").write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    write_tidy(out / TIDY_FILE, tidy_rows(rows))
