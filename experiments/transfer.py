"""Transfer experiment: does a saved Q-table help a robot learn in an arena it has never seen?

For every seed, two robots train in the same arena, from the same seed, for the same budget:

* ``init``: its Q-table starts as a copy of the saved table (standalone or federated);
* ``zero``: its Q-table starts at zero (the usual start).

Both use the same learner settings (default :class:`dfrl.robots.training.TrainerConfig` values,
with the algorithm, sensor grouping, levels and action set read from the table's sidecar),
so the only difference is the initial table. Reported per run and aggregated over seeds:

* collisions per 1,000 training steps, overall, over the first ``min(1000, N)`` steps and over
  the first 10% of the steps (where a head start shows);
* final cumulative reward and mean reward per step;
* a greedy evaluation of the final table (collisions per 1,000 steps and mean reward per
  step, :func:`dfrl.robots.evaluation.evaluate_policy`), and one of the initial table before any
  training (for ``zero`` that is a uniformly random policy: all ties), from the same poses.

Usage::

    from dfrl.experiments.transfer import TransferConfig, run
    result = run(TransferConfig(init="results/r1/q_table.npy", arena="my_arena.json",
                                iterations=3000, seeds=(1, 2, 3, 4, 5)), Path("results/transfer"))
    result.summary["init"]["collisions_per_1000"].mean, result.ratio["collisions_per_1000"]
"""
from __future__ import annotations

import csv
import json
import math
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any

import numpy as np

from dfrl.robots.env import ActionSet
from dfrl.robots.state import DiscretisationConfig
from dfrl.robots.training import TrainerConfig

#: Length of the "head" window in steps (capped by the budget).
HEAD_STEPS: int = 1000
#: Offset between a training seed and the seed of its greedy evaluation.
EVAL_SEED_OFFSET: int = 10_000


class Condition(str, Enum):
    """How the learner's table starts."""

    INIT = "init"  #: a copy of the saved table
    ZERO = "zero"  #: all zeros (the learner's ``initial_q``)


#: Per-run metrics that are aggregated over seeds, in report order.
METRICS: tuple[str, ...] = (
    "collisions_per_1000",
    "head_collisions_per_1000",
    "head10_collisions_per_1000",
    "cumulative_reward",
    "mean_reward",
    "eval_collisions_per_1000",
    "eval_mean_reward",
    "initial_eval_collisions_per_1000",
    "initial_eval_mean_reward",
)


@dataclass(frozen=True)
class TransferConfig:
    """What to transfer where, and for how long.

    Attributes
    ----------
    init : str
        The saved table (``NAME.npy`` with its ``NAME.json`` sidecar; a bare ``.npy`` is
        accepted and then read with the default discretisation and actions).
    arena : str
        Built-in arena name or arena file; it should not be one the table was trained in.
    iterations : int
        Training budget (control steps) per run.
    seeds : tuple[int, ...]
        One ``init`` and one ``zero`` run per seed.
    algo : str or None
        Learner; ``None`` uses the table's algorithm.
    grouping, levels : str or int or None
        Discretisation overrides; ``None`` uses the table's.
    eval_steps : int
        Greedy evaluation steps per table (0 skips the evaluations).
    curve_every : int
        Record cumulative collisions and reward every this many steps (0: ``iterations // 100``).
    jobs : int
        Worker processes (runs are independent; results do not depend on ``jobs``).
    """

    init: str
    arena: str
    iterations: int = 3000
    seeds: tuple[int, ...] = (1, 2, 3)
    algo: str | None = None
    grouping: str | None = None
    levels: int | None = None
    eval_steps: int = 2000
    curve_every: int = 0
    jobs: int = 1

    def __post_init__(self) -> None:
        object.__setattr__(self, "init", str(self.init))
        object.__setattr__(self, "arena", str(self.arena))
        object.__setattr__(self, "seeds", tuple(int(s) for s in self.seeds))
        if self.iterations < 1:
            raise ValueError(f"iterations must be >= 1, got {self.iterations}")
        if not self.seeds:
            raise ValueError("at least one seed is needed")
        if len(set(self.seeds)) != len(self.seeds):
            raise ValueError(f"seeds must be distinct, got {list(self.seeds)}")
        if self.eval_steps < 0 or self.curve_every < 0 or self.jobs < 1:
            raise ValueError("eval_steps and curve_every must be >= 0, jobs >= 1")

    @property
    def every(self) -> int:
        """Curve sampling interval in steps."""
        return self.curve_every or max(1, self.iterations // 100)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        d = asdict(self)
        d["seeds"] = list(self.seeds)
        return d


@dataclass(frozen=True)
class TableInfo:
    """Where the initial table comes from.

    Attributes
    ----------
    path : str
    shape : tuple[int, int]
    algorithm, arena : str or None
        From the sidecar (``None`` for a bare ``.npy``).
    iterations : int or None
    sidecar : bool
        Whether a sidecar described the table.
    extra : dict
        The sidecar's free fields.
    """

    path: str
    shape: tuple[int, int]
    algorithm: str | None
    arena: str | None
    iterations: int | None
    sidecar: bool
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class RunResult:
    """One training run (one seed, one condition).

    Attributes
    ----------
    seed : int
    condition : str
        ``"init"`` or ``"zero"``.
    iterations, collisions : int
    collisions_per_1000 : float
        Over the whole run.
    head_steps : int
        ``min(1000, iterations)``.
    head_collisions_per_1000 : float
        Over the first ``head_steps`` steps.
    head10_steps : int
        ``max(1, iterations // 10)``.
    head10_collisions_per_1000 : float
        Over the first 10% of the steps.
    cumulative_reward : float
        Sum of the rewards over the run.
    mean_reward : float
        ``cumulative_reward / iterations``.
    eval_collisions_per_1000, eval_mean_reward : float
        Greedy policy of the final table (NaN when ``eval_steps`` is 0).
    initial_eval_collisions_per_1000, initial_eval_mean_reward : float
        Greedy policy of the initial table, before training (NaN when ``eval_steps`` is 0);
        for ``zero`` every action ties, so this is a uniformly random policy.
    respawns : int
    wall_time : float
        Seconds of training and evaluation.
    curve_iteration : np.ndarray, shape (points,)
    curve_collisions : np.ndarray, shape (points,)
        Cumulative collisions at ``curve_iteration``.
    curve_reward : np.ndarray, shape (points,)
        Cumulative reward at ``curve_iteration``.
    """

    seed: int
    condition: str
    iterations: int
    collisions: int
    collisions_per_1000: float
    head_steps: int
    head_collisions_per_1000: float
    head10_steps: int
    head10_collisions_per_1000: float
    cumulative_reward: float
    mean_reward: float
    eval_collisions_per_1000: float
    eval_mean_reward: float
    initial_eval_collisions_per_1000: float
    initial_eval_mean_reward: float
    respawns: int
    wall_time: float
    curve_iteration: np.ndarray = field(repr=False)
    curve_collisions: np.ndarray = field(repr=False)
    curve_reward: np.ndarray = field(repr=False)

    #: Columns of the per-seed CSV (the scalar fields).
    CSV_FIELDS = ("seed", "condition", "iterations", "collisions", "collisions_per_1000",
                  "head_steps", "head_collisions_per_1000", "head10_steps",
                  "head10_collisions_per_1000", "cumulative_reward", "mean_reward",
                  "eval_collisions_per_1000", "eval_mean_reward",
                  "initial_eval_collisions_per_1000", "initial_eval_mean_reward", "respawns",
                  "wall_time")

    def scalars(self) -> dict[str, Any]:
        """The CSV fields as a JSON-ready dict."""
        return {k: getattr(self, k) for k in self.CSV_FIELDS}


@dataclass(frozen=True)
class Stat:
    """Mean and sample standard deviation (0 for a single value) over seeds."""

    mean: float
    std: float
    n: int


@dataclass(frozen=True)
class TransferResult:
    """Outputs of :func:`run`.

    Attributes
    ----------
    config : TransferConfig
    trainer_config : TrainerConfig
        The training configuration of both conditions (its ``seed`` is replaced per run).
    table : TableInfo
    arena_name : str
    same_arena : bool
        The target arena has the same name as the arena the table was trained in.
    runs : list[RunResult]
        Seeds in order, ``init`` before ``zero`` for each.
    summary : dict[str, dict[str, Stat]]
        Condition -> metric (see :data:`METRICS`) -> statistics over seeds.
    ratio : dict[str, float]
        Metric -> ``mean(init) / mean(zero)`` (NaN when the zero mean is 0).
    wall_time : float
    output_dir : Path or None
    """

    config: TransferConfig
    trainer_config: TrainerConfig
    table: TableInfo
    arena_name: str
    same_arena: bool
    runs: list[RunResult]
    summary: dict[str, dict[str, Stat]]
    ratio: dict[str, float]
    wall_time: float
    output_dir: Path | None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (NaN written as ``None``); per-run curves are left out."""
        return _json_safe({
            "config": self.config.to_dict(),
            "trainer_config": self.trainer_config.to_dict(),
            "table": asdict(self.table),
            "arena": self.arena_name,
            "same_arena": self.same_arena,
            "runs": [r.scalars() for r in self.runs],
            "summary": {c: {m: asdict(s) for m, s in per.items()} for c, per in self.summary.items()},
            "ratio": self.ratio,
            "wall_time": round(self.wall_time, 3),
            "output_dir": str(self.output_dir) if self.output_dir is not None else None,
        })


def _json_safe(obj: Any) -> Any:
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_json_safe(v) for v in obj]
    return obj


# -- the table and the matching trainer configuration ---------------------------------------
def load_initial_table(path: str | Path) -> tuple[np.ndarray, TableInfo, dict[str, Any] | None]:
    """Read the table to transfer, with its sidecar when there is one.

    Returns
    -------
    q : np.ndarray, shape (n_states, n_actions), float64
    info : TableInfo
    state : dict or None
        The sidecar's discretisation description (``None`` for a bare ``.npy``).

    Raises
    ------
    ValueError
        Missing file, unreadable or inconsistent table, non-finite entries.
    """
    from dfrl.robots.learners import validate_table
    from dfrl.robots.tables import load_table

    p = Path(path)
    npy = p if p.suffix == ".npy" else p.with_name(p.name + ".npy")
    if not npy.exists():
        raise ValueError(f"{npy}: no such table")
    if npy.with_suffix(".json").exists():
        loaded = load_table(npy)
        q, meta = loaded.q, loaded.meta
        info = TableInfo(path=str(npy), shape=tuple(q.shape), algorithm=meta.algorithm,
                         arena=meta.arena, iterations=meta.iterations, sidecar=True,
                         extra=dict(meta.extra))
        state: dict[str, Any] | None = dict(meta.state)
        state["actions"] = list(meta.actions)
        return q, info, state
    try:
        raw = np.load(npy, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise ValueError(f"{npy}: not a readable .npy array ({exc})") from None
    if raw.ndim != 2:
        raise ValueError(f"{npy}: a Q-table is 2-D (n_states, n_actions), got shape {raw.shape}")
    q = validate_table(raw, raw.shape)
    info = TableInfo(path=str(npy), shape=tuple(q.shape), algorithm=None, arena=None,
                     iterations=None, sidecar=False)
    return q, info, None


def trainer_config_for(config: TransferConfig, q: np.ndarray, info: TableInfo,
                       state: dict[str, Any] | None) -> TrainerConfig:
    """The training configuration of both conditions, checked against the table's shape.

    Algorithm (``info``), sensor grouping, levels and action set (``state``, the sidecar's
    discretisation description plus its ``actions`` names) come from the sidecar unless
    overridden in ``config``; everything else is the :class:`TrainerConfig` default.

    Raises
    ------
    ValueError
        The table's shape does not fit the resulting discretisation and action set, or its
        action names match no :class:`dfrl.robots.env.ActionSet`.
    """
    from dfrl.robots.learners import LEARNERS

    base = TrainerConfig()
    algo = config.algo or info.algorithm or base.algo
    if algo not in LEARNERS:
        raise ValueError(f"unknown learner '{algo}'; registered: {sorted(LEARNERS)}")
    grouping = config.grouping or (state or {}).get("grouping") or base.discretisation.grouping
    levels = config.levels or (state or {}).get("levels") or base.discretisation.levels
    disc = DiscretisationConfig(grouping, int(levels))
    actions = base.actions
    if state is not None and "actions" in state:
        names = list(state["actions"])
        matches = [a for a in ActionSet if a.names == names]
        if not matches:
            raise ValueError(f"{config.init}: action names {names} match no action set "
                             f"({', '.join(f'{a.value}: {a.names}' for a in ActionSet)})")
        actions = matches[0]
    expected = (disc.n_states, len(actions.names))
    if tuple(q.shape) != expected:
        src = "its sidecar" if state is not None else "the defaults (no sidecar)"
        raise ValueError(
            f"{config.init}: table shape {tuple(q.shape)} does not fit the trainer: grouping "
            f"'{disc.grouping.value}' x {disc.levels} levels = {disc.n_states} states and "
            f"{len(actions.names)} actions ({actions.value}) need shape {expected} "
            f"(discretisation from {'the overrides' if config.grouping or config.levels else src})")
    return base.replace(arena=config.arena, iterations=config.iterations, algo=algo,
                        discretisation=disc, actions=actions)


# -- one run -----------------------------------------------------------------------------------
def run_one(trainer_config: TrainerConfig, condition: Condition | str, q0: np.ndarray | None,
            seed: int, eval_steps: int, every: int) -> RunResult:
    """Train one robot for ``trainer_config.iterations`` steps from ``q0`` (or zeros).

    Parameters
    ----------
    trainer_config : TrainerConfig
    condition : Condition
        Label only; the start table is ``q0``.
    q0 : np.ndarray, shape (n_states, n_actions), or None
        Initial table; ``None`` keeps the learner's own initialisation (zeros).
    seed : int
        Training seed; the evaluations use ``EVAL_SEED_OFFSET + seed``.
    eval_steps : int
        Greedy evaluation steps (0: no evaluation, NaN figures).
    every : int
        Curve sampling interval.
    """
    from dfrl.robots.evaluation import PolicyKind, evaluate_policy
    from dfrl.robots.training import Trainer

    condition = Condition(condition)
    cfg = trainer_config.replace(seed=int(seed))
    n = cfg.iterations
    head, head10 = min(HEAD_STEPS, n), max(1, n // 10)
    collided = np.zeros(n, dtype=bool)
    points = list(range(every, n + 1, every))
    if not points or points[-1] != n:
        points.append(n)
    curve_c = np.zeros(len(points), dtype=np.int64)
    curve_r = np.zeros(len(points), dtype=np.float64)
    t0 = time.perf_counter()
    with Trainer(cfg) as trainer:
        if q0 is not None:
            trainer.set_q_table(q0)
        start = trainer.q_table.copy()
        k = 0
        for i in range(n):
            m = trainer.step()
            collided[i] = m.collided
            if m.iteration == points[k]:
                curve_c[k], curve_r[k] = m.collisions, m.cumulative_reward
                k += 1
        final = trainer.q_table.copy()
        cum_reward, respawns = trainer.cumulative_reward, trainer.respawns
    nan = float("nan")
    ev_c = ev_r = ev0_c = ev0_r = nan
    if eval_steps > 0:
        ev_seed = EVAL_SEED_OFFSET + int(seed)
        after = evaluate_policy(cfg, PolicyKind.GREEDY, eval_steps, ev_seed, q_table=final)
        before = evaluate_policy(cfg, PolicyKind.GREEDY, eval_steps, ev_seed, q_table=start)
        ev_c, ev_r = after.collisions_per_1000, after.mean_reward
        ev0_c, ev0_r = before.collisions_per_1000, before.mean_reward
    total = int(collided.sum())
    return RunResult(
        seed=int(seed), condition=condition.value, iterations=n, collisions=total,
        collisions_per_1000=1000.0 * total / n,
        head_steps=head, head_collisions_per_1000=1000.0 * int(collided[:head].sum()) / head,
        head10_steps=head10, head10_collisions_per_1000=1000.0 * int(collided[:head10].sum()) / head10,
        cumulative_reward=float(cum_reward), mean_reward=float(cum_reward) / n,
        eval_collisions_per_1000=ev_c, eval_mean_reward=ev_r,
        initial_eval_collisions_per_1000=ev0_c, initial_eval_mean_reward=ev0_r,
        respawns=int(respawns),
        wall_time=round(time.perf_counter() - t0, 3),
        curve_iteration=np.asarray(points, dtype=np.int64), curve_collisions=curve_c,
        curve_reward=curve_r,
    )


def _run_job(args: tuple[dict[str, Any], str, np.ndarray | None, int, int, int]) -> RunResult:
    cfg_dict, condition, q0, seed, eval_steps, every = args
    return run_one(TrainerConfig.from_dict(cfg_dict), condition, q0, seed, eval_steps, every)


# -- aggregation -------------------------------------------------------------------------------
def aggregate(values: list[float]) -> Stat:
    """Mean and sample standard deviation (ddof 1; 0 for one value) of finite values."""
    arr = np.asarray([v for v in values if math.isfinite(v)], dtype=np.float64)
    if arr.size == 0:
        return Stat(float("nan"), float("nan"), 0)
    std = float(arr.std(ddof=1)) if arr.size > 1 else 0.0
    return Stat(float(arr.mean()), std, int(arr.size))


def summarise(runs: list[RunResult]) -> tuple[dict[str, dict[str, Stat]], dict[str, float]]:
    """Statistics per condition and metric, and the ratio of the means (init / zero)."""
    summary = {c.value: {m: aggregate([getattr(r, m) for r in runs if r.condition == c.value])
                         for m in METRICS} for c in Condition}
    ratio = {}
    for m in METRICS:
        a, b = summary["init"][m].mean, summary["zero"][m].mean
        ratio[m] = a / b if math.isfinite(a) and math.isfinite(b) and b != 0 else float("nan")
    return summary, ratio


# -- the experiment ----------------------------------------------------------------------------
def run(config: TransferConfig, output_dir: Path | None = None) -> TransferResult:
    """Train from the saved table and from zeros in ``config.arena``, for every seed.

    Writes, when ``output_dir`` is given: ``config.json`` (this config, the trainer config and
    the table's description), ``runs.csv`` (one row per seed and condition), ``curves.csv``
    (cumulative collisions and reward every ``config.every`` steps), ``summary.json`` and
    ``transfer.png`` (mean cumulative collisions and reward over seeds; needs matplotlib).

    Raises
    ------
    ValueError
        A missing or bad table, an unknown arena or learner, or a table whose shape does not
        fit the trainer.
    """
    from dfrl.arenas import load_arena

    t0 = time.perf_counter()
    q, info, state = load_initial_table(config.init)
    tcfg = trainer_config_for(config, q, info, state)
    spec = load_arena(config.arena)  # ArenaError is a ValueError
    jobs = [(tcfg.to_dict(), cond.value, q if cond is Condition.INIT else None, seed,
             config.eval_steps, config.every)
            for seed in config.seeds for cond in (Condition.INIT, Condition.ZERO)]
    workers = max(1, min(config.jobs, len(jobs)))
    if workers == 1:
        runs = [_run_job(j) for j in jobs]
    else:
        with ProcessPoolExecutor(max_workers=workers) as pool:
            runs = list(pool.map(_run_job, jobs))
    summary, ratio = summarise(runs)
    out = Path(output_dir) if output_dir is not None else None
    result = TransferResult(
        config=config, trainer_config=tcfg, table=info, arena_name=spec.name,
        same_arena=info.arena is not None and info.arena.lower() == spec.name.lower(),
        runs=runs, summary=summary, ratio=ratio, wall_time=time.perf_counter() - t0,
        output_dir=out)
    if out is not None:
        write_outputs(result, out)
    return result


def write_outputs(result: TransferResult, out: Path) -> None:
    """Write ``config.json``, ``runs.csv``, ``curves.csv``, ``summary.json``, ``transfer.png``."""
    out.mkdir(parents=True, exist_ok=True)
    doc = {"transfer": result.config.to_dict(), "trainer": result.trainer_config.to_dict(),
           "table": asdict(result.table), "arena": result.arena_name}
    (out / "config.json").write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    with open(out / "runs.csv", "w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(RunResult.CSV_FIELDS)
        for r in result.runs:
            writer.writerow([repr(v) if isinstance(v, float) else v for v in r.scalars().values()])
    with open(out / "curves.csv", "w", newline="", encoding="utf-8") as fh:
        writer = csv.writer(fh)
        writer.writerow(("seed", "condition", "iteration", "collisions", "cumulative_reward"))
        for r in result.runs:
            for it, c, rew in zip(r.curve_iteration.tolist(), r.curve_collisions.tolist(),
                                  r.curve_reward.tolist()):
                writer.writerow((r.seed, r.condition, it, c, repr(rew)))
    (out / "summary.json").write_text(json.dumps(result.to_dict(), indent=2) + "\n",
                                      encoding="utf-8")
    try:
        plot_transfer(result, out / "transfer.png")
    except ImportError:  # matplotlib is an optional extra
        pass


def plot_transfer(result: TransferResult, path: Path) -> Path:
    """Cumulative collisions and reward against iterations, mean over seeds, min-max band.

    Raises
    ------
    ImportError
        matplotlib is not installed (``pip install dfrl[plot]``).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax_c, ax_r) = plt.subplots(1, 2, figsize=(10, 3.8), constrained_layout=True)
    src = Path(result.table.path).parent.name + "/" + Path(result.table.path).name
    labels = {"init": f"from table ({src})", "zero": "from zeros"}
    for cond, colour in (("init", "tab:blue"), ("zero", "tab:red")):
        runs = [r for r in result.runs if r.condition == cond]
        it = runs[0].curve_iteration
        for ax, name in ((ax_c, "curve_collisions"), (ax_r, "curve_reward")):
            ys = np.stack([getattr(r, name) for r in runs]).astype(np.float64)
            ax.plot(it, ys.mean(axis=0), color=colour, lw=1.4,
                    label=f"{labels[cond]}, mean of {len(runs)}")
            if len(runs) > 1:
                ax.fill_between(it, ys.min(axis=0), ys.max(axis=0), color=colour, alpha=0.18, lw=0)
    ax_c.set_ylabel("cumulative collisions")
    ax_r.set_ylabel("cumulative reward")
    for ax in (ax_c, ax_r):
        ax.set_xlabel("iterations")
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize=8)
    fig.suptitle(f"Transfer into {result.arena_name} ({result.trainer_config.algo})")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


__all__ = ["Condition", "METRICS", "RunResult", "Stat", "TableInfo", "TransferConfig",
           "TransferResult", "aggregate", "load_initial_table", "run", "run_one", "summarise",
           "trainer_config_for", "write_outputs", "plot_transfer"]
