"""The paper's observation tests in words: how the real runs and each control fare, and the
markdown of every test with its verdict and the summary table (used by :mod:`.paper`)."""
from __future__ import annotations

import math

from dfrl.experiments.science.report.standing import MIN_SEEDS, Standing, Test
from dfrl.experiments.science.statistics import Judgement


def real_words(t: Test) -> str:
    """How the real runs fare: holds for every row, or how many hold."""
    n, k = len(t.real), sum(v.passed for v in t.real)
    if n and k == n:
        return f"holds ({k}/{n})"
    return f"holds for {k} of {n}" if n else "no real runs"


def control_words(t: Test) -> str:
    """How the control fares: none, too few seeds, fixed by construction, passes, fails."""
    standing, why = t.standing()
    if not t.has_control:
        return "none"
    if standing is Standing.CANNOT_JUDGE:
        return f"fewer than {MIN_SEEDS} seeds"
    if "fixed by construction" in why:
        return "fixed by construction"
    return "passes" if t.control_passes else "fails"


def control_results(t: Test) -> str:
    """Each control row's result: ``zero table: fails (0.01 ± 0.03 (n=3)); ...``."""
    if not t.control:
        return "none"
    out = []
    for v in t.control:
        if v.measure.n < MIN_SEEDS:
            word = f"{v.measure.n} seed(s)"
        elif v.values and max(v.values) == min(v.values):
            word = "fixed by construction"
        else:
            word = "passes" if v.passed else "fails"
        out.append(f"{v.subject}: {word} ({v.measure})")
    return "; ".join(out)


def summary_markdown(tests: list[Test]) -> list[str]:
    """The summary table: per test, the real rows, every control's result and the standing.
    "yes" only for a test of learning (:meth:`Test.is_test`: at least MIN_SEEDS seeds and a
    control that fails), never with one seed or no control."""
    L = ["| test | real runs (rows that hold, after Holm) | each control's result "
         "(mean ± 95% half width, n) | a test of learning? |", "|---|---|---|---|"]
    for t in tests:
        standing, why = t.standing()
        if standing is Standing.TEST:
            word = "yes" if any(v.passed for v in t.real) else (
                "yes; no real row holds, so it shows no learning at this n")
        else:
            word = f"{standing.value}: {why}"
        L.append(f"| {t.key}. {t.title} | {real_words(t)} | {control_results(t)} | {word} |")
    return L


def tests_markdown(tests: list[Test]) -> list[str]:
    """The tests as markdown: the family Holm's correction ran over, then one table per test
    and its verdict."""
    n = sum(len(t.real) for t in tests)
    L = [f"Verdicts: a row **holds** when its 95% interval lies on the claimed side of the "
         f"bound and its p-value, after Holm's correction over the family of all {n} real-run "
         f"rows below (control rows are checks, not in the family), is under 5%; "
         f"**refuted (effect excluded at 95%)** when the interval lies on the other side; "
         f"otherwise **not significant at n = K (smallest detectable effect D)**, D being the "
         f"true distance from the bound a 5% t test finds with 80% power at that n and spread; "
         f"with fewer than {MIN_SEEDS} seeds the report **cannot judge**. A test is a test of "
         f"learning only when its controls (runs that cannot have learned: the zero table, the "
         f"shuffled-reward runs) can fail (not fixed by construction), all fail, and each "
         f"differs from every real row that holds (real minus control, paired by seed); with "
         f"no control, or fewer than {MIN_SEEDS} seeds, it cannot judge.", ""]
    for t in tests:
        L += [f"### {t.key}. {t.title}", "", f"Measure: {t.how}.", "",
              "| runs | mean ± 95% half width (n seeds) | p (Holm) | verdict | note |",
              "|---|---|---|---|---|"]
        for v in t.real:
            L.append(f"| {v.subject} | {v.measure} | {_p(v.judgement)} | {v.judgement} | "
                     f"{v.note} |")
        for v in t.control:
            L.append(f"| {v.subject} | {v.measure} | {_p(v.judgement, False)} | "
                     f"{v.judgement} | control. {v.note} |")
        standing, why = t.standing()
        L += ["", f"Verdict: the real runs: **{real_words(t)}**; **{standing.value}**: {why}.", ""]
    return L


def _p(j: Judgement, adjusted: bool = True) -> str:
    p = j.p_adjusted if adjusted else j.p
    return "n/a" if math.isnan(p) else f"{p:.2g}"
