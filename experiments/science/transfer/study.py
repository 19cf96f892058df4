"""``dfrl transfer-study``: the paper's transfer claim tested as stated: a robot that starts
from the federated table learns an unseen arena faster and more safely than one that starts
from a standalone table of any of the source arenas.

Source tables, per source seed ``s`` (Q-learning, ``iterations`` per robot):

* ``federated_<method>``: five robots in R1..R5, robot k with the training seed 1000 s + k,
  sharing every ``respite`` iterations (:func:`dfrl.experiments.science.studies.fedsim.federate`);
* ``standalone_r1`` .. ``standalone_r5``: the matched controls, one robot alone in arena k
  with the same training seed 1000 s + k as federated robot k, for the same iterations;
* ``zeros``: no training (a robot learning from scratch).

Learning phase, in every unseen arena (``targets``, h1 and h2 by default) and target seed t: a
robot starts from the source table and learns ``learn`` steps. Its seeds are those of its
source seed (:func:`phase_seeds`): training seed 1,000,000 + 1,000 s + t, evaluation seed
that + 500. So the sources of one source seed learn from the same seeds (paired within the
seed) and different source seeds learn from different ones (independent across seeds; the
``zeros`` source too, whose table is the same for every seed). The greedy score of the
learning table is evaluated at iteration 0 and every ``eval_every`` iterations to the end
(``eval_steps`` seeded steps, the same episodes at every grid point). Measured: **collisions
while learning** (per 1,000 steps, over the whole phase), the **score while learning** (the
area under the score curve over the phase divided by its span, its mean level:
:func:`dfrl.experiments.science.curves.auc`) and, read off the score curve once every phase
has run, the **time to the threshold** (:func:`with_times`): each unseen arena's threshold
(given: ``threshold`` for every arena, ``arena_thresholds`` for some; else derived from
reference runs in that arena alone), lifted above every phase's iteration-0 score in that
arena (:mod:`dfrl.experiments.science.transfer.thresholds`), reached at the first of
``confirm`` (2) evaluations in a row at or above it (the score jumps between evaluations: one
crossing is not learning); a phase that never reaches it is censored at ``learn``.

With ``unpaired`` the controls are trained, and learn, with other seeds (source seed
s + 10,000): the comparisons are then Welch's, not paired
(:mod:`dfrl.experiments.science.transfer.claims`).

``sim`` chooses the simulator (:mod:`dfrl.experiments.science.studies.simulators`): pybullet
runs every reference run, source and learning phase as a job of a process pool of ``jobs``
workers; batched (the default) runs the study in this process, each stage in a few compiled
calls (:mod:`.batched`).
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from dfrl.arenas import load_arena
from dfrl.experiments.science.curves import auc
from dfrl.experiments.science.studies.fedsim import AGGREGATIONS, federate, in_turn
from dfrl.experiments.science.studies.history import eval_job
from dfrl.experiments.science.studies.simulators import BATCHED, DEFAULT_SIM, check_sim
from dfrl.experiments.science.transfer.thresholds import (
    Threshold,
    lift,
    thresholds_for,
    time_to_threshold,
)
from dfrl.robots.training import Trainer, TrainerConfig

ARENAS = ("r1", "r2", "r3", "r4", "r5")
#: Seed offset of the controls' sources (and so of their learning phases) with ``unpaired``.
UNPAIRED_OFFSET = 10_000
#: Learning phase t of pair seed s trains with PHASE_SEED_BASE + PHASE_STRIDE x s + t and is
#: evaluated with that + PHASE_EVAL_OFFSET (so target seeds are below PHASE_EVAL_OFFSET).
PHASE_SEED_BASE = 1_000_000
PHASE_STRIDE = 1_000
PHASE_EVAL_OFFSET = 500
#: Further controls on request (``extra``): one robot in R1 for five times the iterations (the
#: federation's experience), one robot in R1..R5 in turn, the mean of the five standalone tables.
EXTRA = ("standalone_same_experience", "in_turn", "one_shot_average")


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
    sim: str = DEFAULT_SIM

    def __post_init__(self) -> None:
        check_sim(self.sim)
        object.__setattr__(
            self, "arena_thresholds", tuple((str(a), float(v)) for a, v in self.arena_thresholds)
        )
        for name in (
            "iterations",
            "respite",
            "learn",
            "eval_every",
            "eval_steps",
            "episode_steps",
            "confirm",
            "jobs",
            "threshold_iterations",
            "threshold_runs",
        ):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if not self.source_seeds or not self.target_seeds or not self.targets:
            raise ValueError("at least one source seed, target seed and target arena")
        if len(set(self.source_seeds)) != len(self.source_seeds):
            raise ValueError(f"source seeds must be distinct, got {list(self.source_seeds)}")
        if min(self.source_seeds) < 0:
            raise ValueError(f"source seeds must be >= 0, got {list(self.source_seeds)}")
        if not all(0 <= t < PHASE_EVAL_OFFSET for t in self.target_seeds):
            raise ValueError(
                f"target seeds must be in 0..{PHASE_EVAL_OFFSET - 1}, got {list(self.target_seeds)}"
            )
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
            raise ValueError(
                f"a threshold for {stray}, which are not among the target arenas "
                f"{list(self.targets)}"
            )
        if not 0.0 < self.threshold_fraction <= 1.0:
            raise ValueError(f"threshold_fraction must be in (0, 1], got {self.threshold_fraction}")

    @property
    def federated(self) -> str:
        return f"federated_{self.method}"

    @property
    def conditions(self) -> tuple[str, ...]:
        return (
            (self.federated,)
            + tuple(f"standalone_{a}" for a in ARENAS)
            + ("zeros",)
            + tuple(dict.fromkeys(self.extra))
        )

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


def phase_seeds(pair: int, target_seed: int) -> tuple[int, int]:
    """The training and evaluation seeds of learning phase ``target_seed`` of pair seed
    ``pair`` (:func:`pair_seed`): ``PHASE_SEED_BASE + PHASE_STRIDE x pair + target_seed`` and
    that + ``PHASE_EVAL_OFFSET``. The sources of one pair seed share them; no two pair seeds
    do (for target seeds below ``PHASE_EVAL_OFFSET``)."""
    train = PHASE_SEED_BASE + PHASE_STRIDE * int(pair) + int(target_seed)
    return train, train + PHASE_EVAL_OFFSET


def _alone(c: TrainerConfig, sim: str) -> np.ndarray:
    if sim == BATCHED:
        from dfrl.experiments.science.transfer.batched import alone

        return alone(c)
    with Trainer(c) as t:
        for _ in range(c.iterations):
            t.step()
        return t.q_table.copy()


def source_job(condition: str, seed: int, opts: StudyOptions) -> tuple[str, int, np.ndarray]:
    """The source table of one condition and source seed (a worker job), trained on
    ``opts.sim``."""
    s = pair_seed(condition, seed, opts)
    # the two simulators' functions take the same arguments (their annotations differ a little)
    fed: Callable[..., Any]
    turn: Callable[..., Any]
    if opts.sim == BATCHED:
        from dfrl.experiments.science.studies.fedsim_batched import (
            federate_batched,
            in_turn_batched,
        )

        fed, turn = federate_batched, in_turn_batched
    else:
        fed, turn = federate, in_turn

    def cfg(arena: str, k: int) -> TrainerConfig:
        return TrainerConfig(arena=arena, seed=1000 * s + k, iterations=opts.iterations)

    if condition == "zeros":
        c = cfg("r1", 0)
        q = np.zeros((c.discretisation.n_states, len(c.actions.names)))
    elif condition == "standalone_same_experience":
        q = _alone(cfg("r1", 0).replace(iterations=opts.iterations * len(ARENAS)), opts.sim)
    elif condition == "in_turn":
        q = turn(cfg("r1", 0), ARENAS, opts.iterations)
    elif condition == "one_shot_average":
        q = np.mean([_alone(cfg(a, k), opts.sim) for k, a in enumerate(ARENAS)], axis=0)
    elif condition.startswith("standalone_"):
        arena = condition.removeprefix("standalone_")
        q = _alone(cfg(arena, ARENAS.index(arena)), opts.sim)
    elif condition == opts.federated:
        q = fed(
            [cfg(a, k) for k, a in enumerate(ARENAS)], opts.iterations, opts.respite, opts.method
        ).table
    else:
        raise ValueError(f"unknown condition {condition!r}")
    return condition, seed, q


def phase_row(
    condition: str,
    seed: int,
    arena: str,
    tseed: int,
    opts: StudyOptions,
    scores: list[tuple[int, float]],
    collisions: list[tuple[int, int]],
) -> dict[str, Any]:
    """A learning phase's row from its greedy scores and cumulative collisions on the grid."""
    pair = pair_seed(condition, seed, opts)
    train_seed, ev_seed = phase_seeds(pair, tseed)
    return {
        "condition": condition,
        "source_seed": seed,
        "pair_seed": pair,
        "arena": arena,
        "target_seed": tseed,
        "phase_seed": train_seed,
        "eval_seed": ev_seed,
        "collisions_per_1000": 1000.0 * collisions[-1][1] / opts.learn,
        "score_auc": auc([g for g, _ in scores], [v for _, v in scores]),
        "start_score": scores[0][1],
        "scores": scores,
        "collisions": collisions,
    }


def target_job(
    condition: str, seed: int, q: np.ndarray, arena: str, tseed: int, opts: StudyOptions
) -> dict[str, Any]:
    """One learning phase from table ``q`` in ``arena`` on pybullet (a worker job):
    collisions while learning and the greedy score on the whole grid
    (:meth:`StudyOptions.grid`), its mean level over the phase (``score_auc``) and its
    iteration-0 value (``start_score``). (The batched simulator runs every phase at once:
    :func:`.batched.learning_phases`.)"""
    pair = pair_seed(condition, seed, opts)
    train_seed, ev_seed = phase_seeds(pair, tseed)
    ev_cfg = TrainerConfig().to_dict()
    scores: list[tuple[int, float]] = []
    collisions: list[tuple[int, int]] = []
    with Trainer(TrainerConfig(arena=arena, seed=train_seed, iterations=opts.learn)) as t:
        t.set_q_table(q)
        done = 0
        for g in opts.grid():
            for _ in range(g - done):
                t.step()
            done = g
            collisions.append((g, int(t.collisions)))
            ev = eval_job(
                ev_cfg, t.q_table.copy(), arena, opts.eval_steps, opts.episode_steps, ev_seed
            )
            scores.append((g, float(ev["score"])))
    return phase_row(condition, seed, arena, tseed, opts, scores, collisions)


def with_times(
    rows: list[dict[str, Any]], thresholds: dict[str, Threshold], confirm: int, budget: int
) -> tuple[list[dict[str, Any]], dict[str, Threshold]]:
    """Every arena's threshold lifted above the iteration-0 scores of its learning phases
    (:func:`~dfrl.experiments.science.transfer.thresholds.lift`), and each row with its
    arena's ``threshold``, ``threshold_base`` (before the lift), ``threshold_from`` and its
    ``time_to_threshold`` and ``reached`` on its score curve.

    Raises
    ------
    ValueError
        An arena of ``thresholds`` without a learning phase.
    """
    lifted = {
        a: lift(th, [r["start_score"] for r in rows if r["arena"] == a])
        for a, th in thresholds.items()
    }
    out = []
    for r in rows:
        th = lifted[r["arena"]]
        time, reached = time_to_threshold(r["scores"], th.value, confirm, budget)
        out.append(
            {
                **r,
                "threshold": th.value,
                "threshold_base": th.base,
                "threshold_from": th.origin(),
                "time_to_threshold": time,
                "reached": reached,
            }
        )
    return out, lifted


def transfer_study(
    opts: StudyOptions, progress: Callable[[str], None] | None = None
) -> list[dict[str, Any]]:
    """The target arenas' thresholds, every source table, every learning phase, then each
    phase's time to its arena's threshold lifted above every phase's start
    (:func:`with_times`); one row per learning phase."""
    say = progress or (lambda _msg: None)
    for arena in opts.targets:  # an unknown arena fails here, before any training
        load_arena(arena)
    if opts.sim == BATCHED:
        rows, thresholds = _batched_study(opts, say)
    else:
        rows, thresholds = _pybullet_study(opts, say)
    rows, lifted = with_times(rows, thresholds, opts.confirm, opts.learn)
    for th in lifted.values():
        say(f"threshold in {th.arena}: {th.value:.4g} ({th.origin()})")
    return rows


def _pybullet_study(
    opts: StudyOptions, say: Callable[[str], None]
) -> tuple[list[dict[str, Any]], dict[str, Threshold]]:
    """Thresholds, sources and learning phases on ``opts.jobs`` processes."""
    with ProcessPoolExecutor(max_workers=opts.jobs) as pool:
        thresholds = thresholds_for(
            opts.targets,
            opts.given_thresholds(),
            opts.threshold_fraction,
            opts.threshold_iterations,
            opts.threshold_runs,
            opts.eval_steps,
            opts.episode_steps,
            pool,
        )
        for th in thresholds.values():
            say(f"threshold in {th.arena} before the lift: {th.value:.3g} ({th.origin()})")
        jobs = [(c, s, opts) for c in opts.conditions for s in opts.source_seeds]
        srcs = []
        for i, src in enumerate(pool.map(source_job, *zip(*jobs)), 1):
            srcs.append(src)
            say(f"source {i}/{len(jobs)}: {src[0]} seed {src[1]}")
        args = [
            (c, s, q, a, t, opts)
            for c, s, q in srcs
            for a in opts.targets
            for t in opts.target_seeds
        ]
        rows = []
        for i, row in enumerate(pool.map(target_job, *zip(*args)), 1):
            rows.append(row)
            say(
                f"learning phase {i}/{len(args)}: {row['condition']} seed {row['source_seed']} "
                f"in {row['arena']}"
            )
    return rows, thresholds


def _batched_study(
    opts: StudyOptions, say: Callable[[str], None]
) -> tuple[list[dict[str, Any]], dict[str, Threshold]]:
    """Thresholds, sources and learning phases on the batched simulator, in this process:
    the reference runs in one batch, the sources one after the other (milliseconds each),
    every learning phase in one batch (:mod:`.batched`)."""
    from dfrl.experiments.science.transfer.batched import learning_phases

    thresholds = thresholds_for(
        opts.targets,
        opts.given_thresholds(),
        opts.threshold_fraction,
        opts.threshold_iterations,
        opts.threshold_runs,
        opts.eval_steps,
        opts.episode_steps,
        None,
        BATCHED,
    )
    for th in thresholds.values():
        say(f"threshold in {th.arena} before the lift: {th.value:.3g} ({th.origin()})")
    jobs = [(c, s) for c in opts.conditions for s in opts.source_seeds]
    srcs = []
    for i, (c, s) in enumerate(jobs, 1):
        srcs.append(source_job(c, s, opts))
        say(f"source {i}/{len(jobs)}: {c} seed {s}")
    rows = learning_phases(srcs, opts)
    say(f"learning phases: {len(rows)} in one batch")
    return rows, thresholds
