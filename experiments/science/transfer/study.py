"""``dfrl transfer-study``: the paper's transfer claim tested as stated: a robot that starts
from the federated table learns an unseen arena faster and more safely than one that starts
from a standalone table of any of the source arenas.

Source tables, per source seed ``s`` (Q-learning, ``iterations`` per robot):

* ``federated_<method>``: five robots in R1..R5, robot k with the training seed 1000 s + k,
  sharing every ``respite`` iterations (:func:`dfrl.experiments.science.studies.fedsim.federate`);
* ``standalone_r1`` .. ``standalone_r5``: the matched controls, one robot alone in arena k
  with the same training seed 1000 s + k as federated robot k, for the same iterations;
* ``zeros``: no training (a robot learning from scratch).

Learning phase, in every unseen arena (``targets``, h1 and h2 by default) and target seed: a
robot starts from the source table and learns ``learn`` steps (training seed 90,000 + target
seed, the same for every source). Measured: **collisions while learning** (per 1,000 steps,
over the whole phase) and **time to the threshold**: the greedy score of the learning table
is evaluated at iteration 0 and every ``eval_every`` iterations (``eval_steps`` seeded steps,
the same episodes at every grid point), and the time is the first grid point of the first
``confirm`` (2) evaluations in a row at or above ``threshold`` (the score jumps between
evaluations: one crossing is not learning); a run that never reaches it is censored at
``learn``, never counted as reaching it there (evaluations stop once it is reached). Each
unseen arena has its own threshold: given (``threshold`` for every arena,
``arena_thresholds`` for some), else derived from reference runs in that arena alone
(:mod:`dfrl.experiments.science.transfer.thresholds`).

With ``unpaired`` the controls are trained and learn with other seeds (source seed
s + 10,000, target seeds + 5,000): the comparisons are then Welch's, not paired
(:mod:`dfrl.experiments.science.transfer.claims`).
"""
from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from dfrl.arenas import load_arena
from dfrl.experiments.science.studies.fedsim import AGGREGATIONS, federate, in_turn
from dfrl.experiments.science.studies.history import eval_job
from dfrl.experiments.science.transfer.thresholds import Threshold, thresholds_for
from dfrl.robots.training import Trainer, TrainerConfig

ARENAS = ("r1", "r2", "r3", "r4", "r5")
#: Seed offset of the controls' sources (and of their target seeds / 2) with ``unpaired``.
UNPAIRED_OFFSET = 10_000
TARGET_SEED_BASE = 90_000
#: Further controls on request (``extra``): one robot in R1 for five times the iterations (the
#: federation's experience), one robot in R1..R5 in turn, the mean of the five standalone tables.
EXTRA = ("standalone_same_experience", "in_turn", "one_shot_average")
EVAL_SEED_BASE = 80_000


@dataclass(frozen=True)
class StudyOptions:
    """What the study trains and measures (see the module's docs)."""

    source_seeds: tuple[int, ...] = (1, 2, 3, 4, 5)
    target_seeds: tuple[int, ...] = (1,)
    targets: tuple[str, ...] = ("h1", "h2")
    iterations: int = 4000
    respite: int = 500
    method: str = "average"
    learn: int = 2000
    eval_every: int = 100
    eval_steps: int = 300
    episode_steps: int = 200
    threshold: float | None = None
    arena_thresholds: tuple[tuple[str, float], ...] = ()
    threshold_fraction: float = 0.75
    threshold_iterations: int = 8000
    threshold_runs: int = 5
    confirm: int = 2
    unpaired: bool = False
    extra: tuple[str, ...] = ()
    jobs: int = 2

    def __post_init__(self) -> None:
        object.__setattr__(self, "arena_thresholds",
                           tuple((str(a), float(v)) for a, v in self.arena_thresholds))
        for name in ("iterations", "respite", "learn", "eval_every", "eval_steps",
                     "episode_steps", "confirm", "jobs", "threshold_iterations",
                     "threshold_runs"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if not self.source_seeds or not self.target_seeds or not self.targets:
            raise ValueError("at least one source seed, target seed and target arena")
        if len(set(self.source_seeds)) != len(self.source_seeds):
            raise ValueError(f"source seeds must be distinct, got {list(self.source_seeds)}")
        if self.method not in AGGREGATIONS:
            raise ValueError(f"unknown method {self.method!r}; one of {sorted(AGGREGATIONS)}")
        unknown = [c for c in self.extra if c not in EXTRA]
        if unknown:
            raise ValueError(f"unknown extra controls {unknown}; one of {list(EXTRA)}")
        bad = [a for a in self.targets if a in ARENAS]
        if bad:
            raise ValueError(f"target arenas must be unseen, {bad} are source arenas")
        stray = [a for a, _ in self.arena_thresholds if a not in self.targets]
        if stray:
            raise ValueError(f"a threshold for {stray}, which are not among the target arenas "
                             f"{list(self.targets)}")
        if not 0.0 < self.threshold_fraction <= 1.0:
            raise ValueError(f"threshold_fraction must be in (0, 1], got "
                             f"{self.threshold_fraction}")

    @property
    def federated(self) -> str:
        return f"federated_{self.method}"

    @property
    def conditions(self) -> tuple[str, ...]:
        return ((self.federated,) + tuple(f"standalone_{a}" for a in ARENAS) + ("zeros",)
                + tuple(dict.fromkeys(self.extra)))

    def given_thresholds(self) -> dict[str, float]:
        """arena -> its threshold where one was given (``threshold`` for every arena,
        ``arena_thresholds`` over it); the other arenas' are derived."""
        out = {a: self.threshold for a in self.targets} if self.threshold is not None else {}
        return {**out, **dict(self.arena_thresholds)}

    def grid(self) -> list[int]:
        """The evaluation grid of a learning phase: 0, eval_every, ..., learn."""
        g = list(range(0, self.learn + 1, self.eval_every))
        return g if g[-1] == self.learn else g + [self.learn]

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}


def pair_seed(condition: str, seed: int, opts: StudyOptions) -> int:
    """The seed a condition's source is trained with for source seed ``seed``: the same for
    every condition (paired), else shifted for the controls."""
    shifted = opts.unpaired and not condition.startswith("federated_")
    return seed + UNPAIRED_OFFSET if shifted else seed


def _alone(c: TrainerConfig) -> np.ndarray:
    with Trainer(c) as t:
        for _ in range(c.iterations):
            t.step()
        return t.q_table.copy()


def source_job(condition: str, seed: int, opts: StudyOptions) -> tuple[str, int, np.ndarray]:
    """The source table of one condition and source seed (a worker job)."""
    s = pair_seed(condition, seed, opts)

    def cfg(arena: str, k: int) -> TrainerConfig:
        return TrainerConfig(arena=arena, seed=1000 * s + k, iterations=opts.iterations)

    if condition == "zeros":
        with Trainer(cfg("r1", 0)) as t:
            q = np.zeros_like(t.q_table)
    elif condition == "standalone_same_experience":
        q = _alone(cfg("r1", 0).replace(iterations=opts.iterations * len(ARENAS)))
    elif condition == "in_turn":
        q = in_turn(cfg("r1", 0), ARENAS, opts.iterations)
    elif condition == "one_shot_average":
        q = np.mean([_alone(cfg(a, k)) for k, a in enumerate(ARENAS)], axis=0)
    elif condition.startswith("standalone_"):
        arena = condition.removeprefix("standalone_")
        q = _alone(cfg(arena, ARENAS.index(arena)))
    elif condition == opts.federated:
        q = federate([cfg(a, k) for k, a in enumerate(ARENAS)], opts.iterations, opts.respite,
                     opts.method).table
    else:
        raise ValueError(f"unknown condition {condition!r}")
    return condition, seed, q


def target_job(condition: str, seed: int, q: np.ndarray, arena: str, tseed: int,
               opts: StudyOptions, threshold: Threshold) -> dict[str, Any]:
    """One learning phase from table ``q`` in ``arena``: collisions while learning and the
    greedy score on the grid until it reaches ``threshold`` (the arena's)."""
    shift = 5_000 if pair_seed(condition, seed, opts) != seed else 0
    ev_cfg, ev_seed = TrainerConfig().to_dict(), EVAL_SEED_BASE + tseed + shift
    grid = opts.grid()
    scores: list[tuple[int, float]] = []
    collisions: list[tuple[int, int]] = []
    time, reached, run = float(opts.learn), False, 0
    with Trainer(TrainerConfig(arena=arena, seed=TARGET_SEED_BASE + tseed + shift,
                               iterations=opts.learn)) as t:
        t.set_q_table(q)
        done = 0
        for g in grid:
            for _ in range(g - done):
                t.step()
            done = g
            collisions.append((g, int(t.collisions)))
            if not reached:
                ev = eval_job(ev_cfg, t.q_table.copy(), arena, opts.eval_steps,
                              opts.episode_steps, ev_seed)
                scores.append((g, float(ev["score"])))
                run = run + 1 if ev["score"] >= threshold.value else 0
                if run == opts.confirm:
                    time, reached = float(scores[-opts.confirm][0]), True
    return {"condition": condition, "source_seed": seed,
            "pair_seed": pair_seed(condition, seed, opts), "arena": arena,
            "target_seed": tseed,
            "collisions_per_1000": 1000.0 * collisions[-1][1] / opts.learn,
            "time_to_threshold": time, "reached": reached, "threshold": threshold.value,
            "threshold_from": threshold.origin(), "scores": scores, "collisions": collisions}


def transfer_study(opts: StudyOptions,
                   progress: Callable[[str], None] | None = None) -> list[dict[str, Any]]:
    """The target arenas' thresholds, every source table, then every learning phase; one row
    per learning phase (with its arena's ``threshold`` and ``threshold_from``)."""
    say = progress or (lambda _msg: None)
    for arena in opts.targets:          # an unknown arena fails here, before any training
        load_arena(arena)
    with ProcessPoolExecutor(max_workers=opts.jobs) as pool:
        thresholds = thresholds_for(opts.targets, opts.given_thresholds(),
                                      opts.threshold_fraction, opts.threshold_iterations,
                                      opts.threshold_runs, opts.eval_steps, opts.episode_steps,
                                      pool)
        for th in thresholds.values():
            say(f"threshold in {th.arena}: {th.value:.3g} ({th.origin()})")
        jobs = [(c, s, opts) for c in opts.conditions for s in opts.source_seeds]
        srcs = []
        for i, src in enumerate(pool.map(source_job, *zip(*jobs)), 1):
            srcs.append(src)
            say(f"source {i}/{len(jobs)}: {src[0]} seed {src[1]}")
        args = [(c, s, q, a, t, opts, thresholds[a]) for c, s, q in srcs for a in opts.targets
                for t in opts.target_seeds]
        rows = []
        for i, row in enumerate(pool.map(target_job, *zip(*args)), 1):
            rows.append(row)
            say(f"learning phase {i}/{len(args)}: {row['condition']} seed {row['source_seed']} "
                f"in {row['arena']}")
        return rows
