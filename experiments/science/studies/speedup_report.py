"""The speed-up study's numbers and words: Kaplan-Meier times to each target per condition and
N, bootstrap intervals on T(1)/T(N), verdicts on "linear speed-up" and "a speed-up" (Holm over
the whole study), the markdown tables, ``speedup.json`` and the tidy rows
(:mod:`.speedup` runs the federations).
"""

from __future__ import annotations

import zlib
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

from dfrl.experiments.science.censored import CensoredRatio, censored_ratio, km_median_interval
from dfrl.experiments.science.statistics import BootstrapInterval, Judgement, Outcome, adjust, judge
from dfrl.experiments.science.studies.speedup import SpeedupOptions, arenas, measures

#: Fewest seeds per N a verdict is given on.
MIN_SEEDS = 3

THEORY = """What the theory assumes, and what this study uses.
Khodadadian, Sharma, Joshi and Maguluri (ICML 2022) and Woo, Joshi and Chi (ICML 2023) prove
that N agents sampling the *same* MDP (Woo et al.: with different behaviour policies, i.e.
different coverage; not different environments) need N times fewer samples each to estimate
Q* to accuracy epsilon, for small epsilon, when (1) the step size is a small constant chosen
for the target (of the order of N epsilon^2 up to (1 - gamma), mixing-time and log factors,
so it grows with N: the N-fold drop in the variance of the averaged update is spent on
larger steps), (2) the agents average after K local steps with K small enough that the local
drift (of order alpha^2 K^2) stays below epsilon (Woo et al.: about 1/alpha or fewer), and
(3) behaviour is a fixed exploring policy (Markovian samples from a uniformly ergodic chain).
The study uses the project's learner as the robots learn: alpha = {alpha} fixed for every N,
gamma = {gamma}, an epsilon-greedy behaviour on the learnt table with epsilon {eps_start} ->
{eps_end} over {eps_decay} updates, average every K = {share_every} iterations. With alpha
fixed, only the variance of the table shrinks with N; the bias (values still growing from 0,
which falls like (1 - c alpha)^t whatever N) does not, so a target the bias dominates shows
no speed-up and a target near one robot's noise floor the largest. The heterogeneous
condition is outside both theorems: the average of tables from five arenas converges to a
compromise, not to R1's values. For asynchronous sampling Woo et al. weight the average by
visits (importance averaging, --method visit_average): the plain average pulls a pair one
robot never visited towards its initial 0. Test the theory's settings with --alpha,
--share-every and --method (e.g. --alpha 0.05 --share-every 20 --method visit_average)."""


@dataclass(frozen=True)
class SpeedupRow:
    """One (condition, measure, N) line of the tables.

    ``time`` is the Kaplan-Meier median iterations per robot with its bootstrap interval,
    ``ratio`` T(1)/T(N) (None at N = 1), ``linear`` the verdict on "T(1)/T(N) > fraction x N"
    and ``faster`` on "T(1)/T(N) > 1" (Holm-adjusted over the study)."""

    condition: str
    measure: str
    robots: int
    arenas: tuple[str, ...]
    reached: int
    runs: int
    time: BootstrapInterval
    ratio: CensoredRatio | None
    linear: Judgement | None
    faster: Judgement | None

    @property
    def total(self) -> float:
        """Samples over all robots, N x T (KM median)."""
        return self.robots * self.time.estimate


def _seed(*parts: Any) -> int:
    return zlib.crc32("/".join(map(str, parts)).encode())


def group(
    results: Mapping[tuple[tuple[str, ...], int], dict[str, Any]],
    condition: str,
    n: int,
    measure: str,
    seeds: Sequence[int],
) -> tuple[list[float], list[bool]]:
    """The runs' times to ``measure`` and whether they reached it (censored at the budget)."""
    runs = [results[(arenas(condition, n), s)] for s in seeds]
    times = [r["times"][measure] for r in runs]
    return (
        [float(r["budget"] if t is None else t) for r, t in zip(runs, times)],
        [t is not None for t in times],
    )


def analyse(
    opts: SpeedupOptions, results: Mapping[tuple[tuple[str, ...], int], dict[str, Any]]
) -> list[SpeedupRow]:
    """Every table row; the verdicts Holm-adjusted as one family."""
    rows: list[SpeedupRow] = []
    for cond in opts.conditions:
        for m in measures(opts):
            one = group(results, cond, 1, m, opts.seeds)
            for n in opts.robots:
                t, e = group(results, cond, n, m, opts.seeds)
                time_ = km_median_interval(t, e, opts.resamples, _seed(cond, m, n))
                ratio = linear = faster = None
                if n > 1:
                    ratio = censored_ratio(one, (t, e), opts.resamples, _seed(cond, m, n, "r"))
                    linear = judge(ratio, opts.linear_fraction * n, "above", MIN_SEEDS)
                    faster = judge(ratio, 1.0, "above", MIN_SEEDS)
                rows.append(
                    SpeedupRow(
                        cond, m, n, arenas(cond, n), sum(e), len(e), time_, ratio, linear, faster
                    )
                )
    family = [j for r in rows for j in (r.linear, r.faster) if j is not None]
    adjusted = iter(adjust(family))
    return [
        replace(
            r,
            linear=None if r.linear is None else next(adjusted),
            faster=None if r.faster is None else next(adjusted),
        )
        for r in rows
    ]


def progress_line(run: dict[str, Any]) -> str:
    """One finished federation in a line (progress output)."""
    times = ", ".join(f"{m} {'-' if t is None else t}" for m, t in run["times"].items())
    return (
        f"N={run['robots']} seed {run['seed']} ({'+'.join(run['arenas'])}): "
        f"{run['iterations']} iterations, {run['seconds']:.0f} s; {times}"
    )


def verdict(j: Judgement | None, claim: str) -> str:
    """The verdict in the study's words (``claim`` + " holds" when it holds)."""
    if j is None:
        return "(baseline)"
    return f"{claim} holds" if j.outcome is Outcome.HOLDS else j.words()


def _num(x: float) -> str:
    return "> budget" if x == float("inf") else f"{x:,.0f}"


def _ival(b: BootstrapInterval, fmt: str = ",.0f", inf: str = "> budget") -> str:
    def one(x: float) -> str:
        return inf if x == float("inf") else "undefined" if x != x else format(x, fmt)

    return f"{one(b.estimate)} [{one(b.low)}, {one(b.high)}]"


def _ratio(r: CensoredRatio) -> str:
    sign = {"at least": ">= ", "at most": "<= "}.get(r.known, "")
    return sign + _ival(r, ".2f", "inf")


def markdown(
    rows: Sequence[SpeedupRow], opts: SpeedupOptions, wall_s: float, reference_name: str
) -> str:
    """The study's report: design, one table per condition, the theory's settings."""
    from dfrl.experiments.science.studies.speedup import base_config

    cfg = base_config(opts)
    eps = cfg.learner.epsilon
    L = [
        f"Speed-up against the number of robots ({opts.sim} simulator): {len(opts.seeds)} "
        f"seeds per N "
        f"({', '.join(map(str, opts.seeds))}), budget {opts.iterations:,} iterations per "
        f"robot{''.join(f' ({b:,} at N = {n})' for n, b in opts.budgets)}, share "
        f"({opts.method}) every {opts.share_every}, table error against "
        f"{reference_name} every {opts.grid} iterations, greedy score in r1 every "
        f"{opts.score_every} ({opts.eval_steps} steps; the first of {opts.score_hold} "
        f"evaluations in a row at or above the threshold). T = Kaplan-Meier median "
        f"iterations per robot to the target (runs that never reach it are censored at the "
        f"budget, '> budget': the median is beyond it; a ratio '>= x' is a bound); "
        f"intervals: 95% percentile bootstrap "
        f"({opts.resamples} resamples, seeds resampled within each N); verdicts Holm-adjusted "
        f"over all {2 * sum(1 for r in rows if r.ratio is not None)} claims. Wall time "
        f"{wall_s:.0f} s.",
        "",
    ]
    for cond in opts.conditions:
        L += [
            f"### {cond}",
            "",
            "| measure | N | arenas | reached | T(N) per robot [95%] | total N x T | "
            f"T(1)/T(N) [95%] | linear: > {opts.linear_fraction:g} N | verdict (linear) | "
            "verdict (any speed-up, > 1) |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in (r for r in rows if r.condition == cond):
            ar = "+".join(f"{r.arenas.count(a)}x{a}" for a in dict.fromkeys(r.arenas))
            L.append(
                f"| {r.measure} | {r.robots} | {ar} | {r.reached}/{r.runs} | "
                f"{_ival(r.time)} | {_num(r.total)} | "
                f"{'-' if r.ratio is None else _ratio(r.ratio)} | "
                f"{opts.linear_fraction * r.robots:g} | "
                f"{verdict(r.linear, 'linear speed-up')} | "
                f"{verdict(r.faster, 'speed-up')} |"
            )
        L.append("")
    L.append(
        "A smallest detectable effect D of a ratio is a factor: a true T(1)/T(N) that "
        "differs from the bound by a factor D is found with 80% power."
    )
    L += [
        "",
        THEORY.format(
            alpha=cfg.learner.alpha,
            gamma=cfg.learner.gamma,
            eps_start=eps.start,
            eps_end=eps.end,
            eps_decay=eps.decay_steps,
            share_every=opts.share_every,
        ),
    ]
    return "\n".join(L)


def _finite(x: float) -> float | str:
    return x if x == x and abs(x) != float("inf") else str(x)


def to_json(
    rows: Sequence[SpeedupRow],
    opts: SpeedupOptions,
    results: Mapping[tuple[tuple[str, ...], int], dict[str, Any]],
    extra: dict[str, Any],
) -> dict[str, Any]:
    """``speedup.json``: options, rows (estimates, intervals, verdicts), every run."""

    def j(x: Judgement | None) -> dict[str, Any] | None:
        return (
            None
            if x is None
            else {
                "outcome": x.outcome.value,
                "words": x.words(),
                "bound": x.bound,
                "p": x.p,
                "p_adjusted": x.p_adjusted,
            }
        )

    out_rows = [
        {
            "condition": r.condition,
            "measure": r.measure,
            "robots": r.robots,
            "arenas": list(r.arenas),
            "reached": r.reached,
            "runs": r.runs,
            "time": {k: _finite(getattr(r.time, k)) for k in ("estimate", "low", "high")},
            "total": _finite(r.total),
            "ratio": None
            if r.ratio is None
            else {
                **{k: _finite(getattr(r.ratio, k)) for k in ("estimate", "low", "high")},
                "known": r.ratio.known,
            },
            "linear": j(r.linear),
            "speedup": j(r.faster),
        }
        for r in rows
    ]
    runs = [
        {
            **v,
            "conditions": [
                c for c in opts.conditions if arenas(c, v["robots"]) == tuple(v["arenas"])
            ],
        }
        for v in results.values()
    ]
    opt = {k: list(v) if isinstance(v, tuple) else v for k, v in vars(opts).items()}
    return {"format": "dfrl-speedup/1", "options": opt, **extra, "rows": out_rows, "runs": runs}


def tidy_rows(
    opts: SpeedupOptions, results: Mapping[tuple[tuple[str, ...], int], dict[str, Any]]
) -> Iterator[tuple]:
    """Rows of :mod:`..tidy`: each run's error curve (``relative_error@r1``, the mean over
    its robots in R1) and greedy score of robot 0 (``score@r1``), once per condition it
    belongs to (N = 1 in both)."""
    for cond in opts.conditions:
        for n in opts.robots:
            for s in opts.seeds:
                r = results[(arenas(cond, n), s)]
                run = f"{cond}/N={n}"
                for it, v in zip(r["grid"], r["error"]):
                    yield (run, s, cond, "r1 robots", int(it), "relative_error@r1", float(v))
                for it, v in zip(r["score_iterations"], r["score"]):
                    yield (run, s, cond, "robot 0", int(it), "score@r1", float(v))
