"""``dfrl speedup``: samples to reach a fixed table error (and a greedy score) against the
number of robots N, in a homogeneous and a heterogeneous federation, compared with the linear
speed-up of the theory (Khodadadian et al. 2022; Woo, Joshi and Chi 2023).

**Design.** Every run is one in-process federation (:func:`.fedsim.federate`, or on the batched
simulator, the default ``sim``, :func:`.fedsim_batched.federate_batched`): N robots learn
Q-learning and share (``method``, default ``average``) every ``share_every`` iterations. The
*target arena* is R1, the arena of the shipped reference table (:mod:`..reference`):

* ``homogeneous``: all N robots in R1 (the theory's setting: one MDP);
* ``heterogeneous``: robot k in ``r1, r2, r3, r4, r5`` in turn (the paper's arenas; N = 10 has
  two robots in each), so robot 0 is always in R1.

N = 1 is the same single robot in R1 in both conditions (it is run once and counts in both):
T(1) is one robot learning R1 alone, and T(1)/T(N) asks how much N - 1 partners, in R1 or in
other arenas, shorten that. Robot k of seed s has the training seed ``1000 s + k`` whatever N.

**Measures**, on a grid of ``grid`` iterations per robot (default 100, finer than the share
period): the relative table error (:func:`..reference.table_error`) of each robot in R1
against the R1 reference, averaged over those robots; every ``score_every`` iterations the
greedy score of robot 0's table in R1 (``eval_steps`` seeded steps, the same episodes for every
N). The time to an error target is the first grid point at or below it; the time to the score
threshold the first of ``score_hold`` consecutive evaluations at or above it. A run stops when
it has reached every target or at the budget ``iterations``; one that never reached a target is
*censored* at the budget (:mod:`..statistics`: Kaplan-Meier medians, ratio bootstrap), never
counted as reaching it there.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import as_completed
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from dfrl.experiments.science.curves import first_reach
from dfrl.experiments.science.pool import stop_pool, study_pool
from dfrl.experiments.science.reference import Reference, table_error
from dfrl.experiments.science.studies.history import eval_many
from dfrl.experiments.science.studies.simulators import (
    DEFAULT_SIM,
    LEGACY_SIM,
    check_same,
    check_sim,
    federator,
)
from dfrl.robots.training import TrainerConfig

PAPER_ARENAS = ("r1", "r2", "r3", "r4", "r5")
TARGET_ARENA = "r1"
CONDITIONS = ("homogeneous", "heterogeneous")
#: The reference the error is measured against (shipped: science/references/).
REFERENCE: dict[str, Any] = {
    "arena": TARGET_ARENA,
    "algo": "qlearning",
    "iterations": 50_000,
    "seeds": (1, 2, 3, 4, 5),
}
#: Seed of the greedy evaluations' episodes (the same for every run).
EVAL_SEED = 70_000


@dataclass(frozen=True)
class SpeedupOptions:
    """What ``dfrl speedup`` runs (defaults: science/README.md, "Speed-up")."""

    robots: tuple[int, ...] = (1, 2, 5, 10)
    seeds: tuple[int, ...] = tuple(range(1, 11))
    conditions: tuple[str, ...] = CONDITIONS
    iterations: int = 12_000
    budgets: tuple[tuple[int, int], ...] = ((1, 36_000),)
    share_every: int = 500
    grid: int = 100
    targets: tuple[float, ...] = (0.75, 0.70)
    score_threshold: float = 0.7
    score_every: int = 500
    score_hold: int = 2
    eval_steps: int = 500
    episode_steps: int = 200
    alpha: float | None = None
    method: str = "average"
    linear_fraction: float = 0.5
    resamples: int = 4000
    jobs: int = 2
    sim: str = DEFAULT_SIM

    def check(self) -> None:
        """Raises ValueError naming the first bad option."""
        check_sim(self.sim)
        bad = [c for c in self.conditions if c not in CONDITIONS]
        if bad or not self.conditions:
            raise ValueError(f"conditions: some of {', '.join(CONDITIONS)}, got {bad}")
        if not self.robots or min(self.robots) < 1 or 1 not in self.robots:
            raise ValueError(
                f"robots: counts >= 1 including 1 (T(1) is the baseline), got {self.robots}"
            )
        if len(set(self.robots)) != len(self.robots) or len(set(self.seeds)) != len(self.seeds):
            raise ValueError("robots and seeds must not repeat")
        for name in (
            "iterations",
            "share_every",
            "grid",
            "score_every",
            "score_hold",
            "eval_steps",
            "episode_steps",
            "resamples",
            "jobs",
        ):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if any(n < 1 or b < 1 for n, b in self.budgets):
            raise ValueError(
                f"budgets: pairs (N, iterations) of positive numbers, got {self.budgets}"
            )
        if self.score_every % self.grid:
            raise ValueError(
                f"score_every ({self.score_every}) must be a multiple of grid ({self.grid})"
            )
        if not self.targets or not all(0 < t < 1 for t in self.targets):
            raise ValueError(f"targets: relative errors in (0, 1), got {self.targets}")
        if self.alpha is not None and not 0 < self.alpha <= 1:
            raise ValueError(f"alpha must be in (0, 1], got {self.alpha}")
        if not 0 < self.linear_fraction <= 1:
            raise ValueError(f"linear_fraction must be in (0, 1], got {self.linear_fraction}")


def parse_budget(text: str) -> tuple[int, int]:
    """``N=ITERATIONS`` (``--budget``) as a pair; ValueError otherwise."""
    n, _, it = text.partition("=")
    if not (n.strip().isdigit() and it.strip().isdigit()):
        raise ValueError(f"expected N=ITERATIONS, got {text!r}")
    return int(n), int(it)


def budget(opts: SpeedupOptions, n: int) -> int:
    """Iterations per robot at N = ``n``: ``opts.budgets`` for the N it names, else
    ``opts.iterations`` (one robot alone needs the longest: its censored runs would leave
    T(1), the numerator of every ratio, open)."""
    return dict(opts.budgets).get(n, opts.iterations)


def arenas(condition: str, n: int) -> tuple[str, ...]:
    """The arena of each of the ``n`` robots (robot 0 always in the target arena)."""
    if condition == "homogeneous":
        return (TARGET_ARENA,) * n
    if condition == "heterogeneous":
        return tuple(PAPER_ARENAS[k % len(PAPER_ARENAS)] for k in range(n))
    raise ValueError(f"condition: one of {', '.join(CONDITIONS)}, got {condition!r}")


def measures(opts: SpeedupOptions) -> list[str]:
    """Names of the times measured: ``error<=0.75``, ..., ``score>=0.7``."""
    return [f"error<={t:g}" for t in opts.targets] + [f"score>={opts.score_threshold:g}"]


def base_config(opts: SpeedupOptions) -> TrainerConfig:
    """The training configuration every robot shares (arena and seed apart)."""
    base = TrainerConfig(iterations=opts.iterations)
    if opts.alpha is not None:
        base = base.replace(learner=replace(base.learner, alpha=opts.alpha))
    return base


def score_time(
    its: Sequence[int], scores: Sequence[float], threshold: float, hold: int
) -> int | None:
    """The first evaluation that starts ``hold`` consecutive ones at or above ``threshold``
    (None: censored)."""
    for k in range(len(scores) - hold + 1):
        if all(s >= threshold for s in scores[k : k + hold]):
            return int(its[k])
    return None


def run_one(
    arena_list: tuple[str, ...], seed: int, opts: SpeedupOptions, reference: Reference
) -> dict[str, Any]:
    """One federation: its error and score curves and its time to each target (None: not
    reached within the budget)."""
    base = base_config(opts)
    cfgs = [base.replace(arena=a, seed=1000 * seed + k) for k, a in enumerate(arena_list)]
    in_target = [k for k, a in enumerate(arena_list) if a == TARGET_ARENA]
    grid: list[int] = []
    error: list[float] = []
    score_its: list[int] = []
    scores: list[float] = []
    base_dict = base.to_dict()

    def reached_all() -> bool:
        return (
            bool(error)
            and min(error) <= min(opts.targets)
            and score_time(score_its, scores, opts.score_threshold, opts.score_hold) is not None
        )

    def observe(it: int, trainers: Sequence[Any]) -> bool:
        grid.append(it)
        error.append(
            float(
                np.mean([table_error(trainers[k].q_table, reference).relative for k in in_target])
            )
        )
        if it % opts.score_every == 0:
            score_its.append(it)
            scores.append(
                eval_many(
                    base_dict,
                    [trainers[0].q_table],
                    [TARGET_ARENA],
                    opts.eval_steps,
                    opts.episode_steps,
                    EVAL_SEED,
                    opts.sim,
                )[0]["score"]
            )
        return reached_all()

    t0 = time.perf_counter()
    fed = federator(opts.sim)(
        cfgs,
        budget(opts, len(cfgs)),
        opts.share_every,
        opts.method,
        observe=observe,
        observe_every=opts.grid,
        final_share=False,
    )
    times: dict[str, int | None] = {}
    for t in opts.targets:
        hit = (
            first_reach(grid, error, t, "below")
            if len(grid) > 1
            else (grid[0] if grid and error[0] <= t else None)
        )
        times[f"error<={t:g}"] = None if hit is None else int(hit)
    times[f"score>={opts.score_threshold:g}"] = score_time(
        score_its, scores, opts.score_threshold, opts.score_hold
    )
    return {
        "robots": len(arena_list),
        "arenas": list(arena_list),
        "seed": seed,
        "iterations": fed.iterations,
        "budget": budget(opts, len(cfgs)),
        "grid": grid,
        "error": error,
        "score_iterations": score_its,
        "score": scores,
        "times": times,
        "seconds": time.perf_counter() - t0,
    }


#: The options a federation's result depends on (the rest only change the analysis).
RUN_OPTIONS = (
    "iterations",
    "share_every",
    "grid",
    "targets",
    "score_threshold",
    "score_every",
    "score_hold",
    "eval_steps",
    "episode_steps",
    "alpha",
    "method",
    "sim",
)
#: One finished federation per line, appended as each ends (``--out``).
RUNS_FILE = "speedup_runs.jsonl"


def recipe(opts: SpeedupOptions, n: int) -> dict[str, Any]:
    """What a federation of ``n`` robots depends on besides its arenas and seed (JSON-ready;
    ``iterations`` is its budget)."""
    out = {
        k: list(v) if isinstance(v, tuple) else v
        for k, v in ((k, getattr(opts, k)) for k in RUN_OPTIONS)
    }
    return {**out, "iterations": budget(opts, n)}


def runs_needed(opts: SpeedupOptions) -> list[tuple[tuple[str, ...], int]]:
    """The distinct federations (arena list, seed) the study runs, the smallest N first (so
    a study stopped early holds whole N), N = 1 and any N whose arenas coincide across
    conditions once."""
    keys = {(arenas(c, n), s) for c in opts.conditions for n in opts.robots for s in opts.seeds}
    return sorted(keys, key=lambda k: (len(k[0]), k[0], k[1]))


def run_all(
    opts: SpeedupOptions,
    reference: Reference,
    progress: Callable[[int, int, dict[str, Any]], None] | None = None,
    done: Mapping[tuple[tuple[str, ...], int], dict[str, Any]] | None = None,
    record: Path | None = None,
) -> dict[tuple[tuple[str, ...], int], dict[str, Any]]:
    """Every federation of the study on ``opts.jobs`` processes; by (arenas, seed). Those in
    ``done`` (:func:`load_runs`) are reused; each new one is appended to ``record`` (a
    :data:`RUNS_FILE`) as it ends, with :func:`recipe`.

    Raises
    ------
    KeyboardInterrupt
        Ctrl-C or SIGTERM (when the caller turns it into one): pending runs are cancelled and
        the workers ended; the finished ones are in ``record``.
    """
    opts.check()
    keys = runs_needed(opts)
    out = {k: v for k, v in (done or {}).items() if k in keys}
    todo = [k for k in keys if k not in out]

    def finished(k: tuple[tuple[str, ...], int], r: dict[str, Any]) -> None:
        out[k] = r
        if record is not None:
            with open(record, "a", encoding="utf-8") as fh:
                fh.write(json.dumps({"recipe": recipe(opts, len(k[0])), **r}) + "\n")
        if progress is not None:
            progress(len(out), len(keys), r)

    if opts.jobs <= 1:
        for k in todo:
            finished(k, run_one(k[0], k[1], opts, reference))
        return out
    pool = study_pool(opts.jobs)
    try:
        futures = {pool.submit(run_one, k[0], k[1], opts, reference): k for k in todo}
        for fut in as_completed(futures):
            finished(futures[fut], fut.result())
    except BaseException:
        stop_pool(pool)
        raise
    pool.shutdown()
    return out


def load_runs(
    path: str | Path, opts: SpeedupOptions, complete: bool = True
) -> dict[tuple[tuple[str, ...], int], dict[str, Any]]:
    """The federations a study recorded (a :data:`RUNS_FILE`) that these options would run
    with the same :func:`recipe`, by (arenas, seed); the last line of a federation wins.

    Raises
    ------
    SimulatorMismatch
        A federation of the file ran on another simulator than ``opts.sim`` (a line without
        one ran on pybullet); the message names the line.
    ValueError
        ``complete`` and a federation the options need is missing (or was run with other
        options), or a line is not JSON (the message names the line).
    OSError
        The file cannot be read.
    """
    needed, out = set(runs_needed(opts)), {}
    lines = Path(path).read_text(encoding="utf-8").splitlines()
    for no, line in enumerate(lines, 1):
        if not line.strip():
            continue
        try:
            r = json.loads(line)
        except ValueError as exc:
            raise ValueError(f"{path}:{no}: not a JSON line ({exc})") from exc
        ran = {"sim": LEGACY_SIM, **(r.get("recipe") or {})}
        check_same(ran["sim"], opts.sim, f"{path}:{no}")
        key = (tuple(r["arenas"]), int(r["seed"]))
        if key in needed and ran == recipe(opts, len(key[0])):
            out[key] = {k: v for k, v in r.items() if k != "recipe"}
    missing = [k for k in runs_needed(opts) if k not in out]
    if complete and missing:
        k = missing[0]
        raise ValueError(
            f"{path}: {len(missing)} federations these options need are missing "
            f"or were run with other options, e.g. {'+'.join(k[0])} seed {k[1]}"
        )
    return out


def study_runs(
    opts: SpeedupOptions,
    reference: Reference,
    out: Path | None,
    resume: bool,
    from_runs: Path | None,
    progress: Callable[[int, int, dict[str, Any]], None] | None = None,
) -> dict[tuple[tuple[str, ...], int], dict[str, Any]]:
    """The federations of ``dfrl speedup``: read from ``from_runs`` alone, or run, each
    appended to ``out/``:data:`RUNS_FILE` when ``out`` is given, reusing those already there
    with ``resume``. A file of federations of another simulator is refused
    (:class:`~.simulators.SimulatorMismatch`), resumed or appended to."""
    if from_runs is not None:
        return load_runs(from_runs, opts)
    record = None if out is None else Path(out) / RUNS_FILE
    found = (
        load_runs(record, opts, complete=False) if record is not None and record.is_file() else {}
    )
    done = found if resume else {}
    if record is not None:
        record.parent.mkdir(parents=True, exist_ok=True)
    return run_all(opts, reference, progress, done, record)
