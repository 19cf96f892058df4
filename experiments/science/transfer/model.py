"""The transfer experiment's configuration and results (dataclasses, JSON form)."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any

import numpy as np

from dfrl.robots.training import TrainerConfig

#: Length of the "head" window in steps (capped by the budget).
HEAD_STEPS: int = 1000


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
    algo, arena : str or None
        The learner's registered name and the arena, from the sidecar (``None`` for a bare
        ``.npy``).
    iterations : int or None
    sidecar : bool
        Whether a sidecar described the table.
    extra : dict
        The sidecar's free fields.
    """

    path: str
    shape: tuple[int, int]
    algo: str | None
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
    CSV_FIELDS = (
        "seed",
        "condition",
        "iterations",
        "collisions",
        "collisions_per_1000",
        "head_steps",
        "head_collisions_per_1000",
        "head10_steps",
        "head10_collisions_per_1000",
        "cumulative_reward",
        "mean_reward",
        "eval_collisions_per_1000",
        "eval_mean_reward",
        "initial_eval_collisions_per_1000",
        "initial_eval_mean_reward",
        "respawns",
        "wall_time",
    )

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
        return json_safe(
            {
                "config": self.config.to_dict(),
                "trainer_config": self.trainer_config.to_dict(),
                "table": asdict(self.table),
                "arena": self.arena_name,
                "same_arena": self.same_arena,
                "runs": [r.scalars() for r in self.runs],
                "summary": {
                    c: {m: asdict(s) for m, s in per.items()} for c, per in self.summary.items()
                },
                "ratio": self.ratio,
                "wall_time": round(self.wall_time, 3),
                "output_dir": str(self.output_dir) if self.output_dir is not None else None,
            }
        )


def json_safe(obj: Any) -> Any:
    """``obj`` with non-finite floats as ``None`` (JSON has no NaN)."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    return obj
