"""A steppable training loop: one :meth:`Trainer.step` = one 64 ms control iteration.

The federated layer drives :class:`Trainer` from its own loop and reads/replaces what the robot
learnt between steps. Every learner offers the flat parameter vector (``params``,
``param_layout``, ``set_params``, ``samples``); tabular learners also the Q-table
(``q_table``, ``set_q_table``, ``visits``), which the function-approximation learners
(``linear``, ``dqn``: ``learner_kind == "function"``) do not have. ``step()`` never blocks or
prints.

Collision handling (the robots run continuously, as in the paper): a step that ends in contact
with a wall or a block is counted, penalised, treated as terminal for the TD update (no
bootstrap), and the robot respawns at a random free pose. If the robot moves less than
``stuck_distance`` in ``stuck_steps`` steps it also respawns (a truncation: the update still
bootstraps). ``iteration`` keeps counting across respawns.

With ``reward_shuffle`` (the learning control) the update learns from a shuffled outcome,
by default its reward centred and every update terminal (``reward_shuffle_mode``,
:mod:`dfrl.robots.reward_shuffle`), while the robot still respawns after a collision and the
metrics keep the reward earned.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from dfrl.robots.approx import FunctionLearner, Layout, validate_params
from dfrl.robots.env import EPuckEnv
from dfrl.robots.learners import TabularLearner, learner_class, make_learner
from dfrl.robots.plugins import options as plugin_options
from dfrl.robots.reward_shuffle import RewardShuffle
from dfrl.robots.metrics import (
    METRIC_DTYPE,
    StepMetrics,
    read_metrics_csv,  # noqa: F401
    write_metrics_csv,
)
from dfrl.robots.state import Discretiser
from dfrl.robots.tables import ParamsMeta, TableMeta, save_params, save_table
from dfrl.robots.trainer_config import DEMO_ITERATIONS, TrainerConfig, to_jsonable  # noqa: F401

# TrainerConfig, DEMO_ITERATIONS (robots/trainer_config.py) and StepMetrics, the metrics CSV
# (robots/metrics.py) are imported here too: callers find them in this module.


def build_learner(
    config: TrainerConfig, n_states: int, obs_dim: int, n_actions: int, rng: np.random.Generator
) -> TabularLearner | FunctionLearner:
    """The learner ``config.algo`` names: tabular over ``n_states`` states, or over the
    ``obs_dim`` raw readings with its own configuration (the ``TrainerConfig`` field its class
    names in ``config_field``)."""
    cls = learner_class(config.algo)
    if issubclass(cls, TabularLearner):
        return make_learner(config.algo, n_states, n_actions, config.learner, rng)
    options = (
        {"config": getattr(config, cls.config_field)}
        if cls.config_field
        else plugin_options(config.algo)
    )
    return make_learner(config.algo, obs_dim, n_actions, config.learner, rng, **options)


class Trainer:
    """One robot learning in one arena, advanced one control step at a time.

    Parameters
    ----------
    config : TrainerConfig

    Attributes
    ----------
    env : EPuckEnv
    discretiser : Discretiser
    learner : TabularLearner or FunctionLearner
    """

    def __init__(self, config: TrainerConfig | None = None) -> None:
        self.config = config or TrainerConfig()
        c = self.config
        # a third stream only for the shuffle: the first two are the same with or without it
        env_seq, learner_seq, shuffle_seq = np.random.SeedSequence(c.seed).spawn(3)
        #: Negative control (``reward_shuffle``): what the learner learns from instead of the
        #: reward earned; None in an ordinary run.
        self.reward_shuffle = (
            RewardShuffle(
                c.reward_shuffle, np.random.default_rng(shuffle_seq), c.reward_shuffle_mode
            )
            if c.reward_shuffle
            else None
        )
        #: The reward and end-of-episode flag the last update learnt from (the ones observed
        #: unless shuffled).
        self.learned_reward, self.learned_terminal = 0.0, False
        self.env = EPuckEnv(arena=c.arena, config=c.env_config())
        self.discretiser = Discretiser(c.discretisation)
        n_actions = int(self.env.action_space.n)
        self.learner: TabularLearner | FunctionLearner = build_learner(
            c,
            self.discretiser.n_states,
            int(self.env.observation_space.shape[0]),
            n_actions,
            np.random.default_rng(learner_seq),
        )
        self._tabular = isinstance(self.learner, TabularLearner)
        obs, _ = self.env.reset(seed=int(env_seq.generate_state(1)[0]))
        self._state = self.discretiser(obs)
        self._obs = np.array(obs, dtype=np.float64)
        self._action = (
            self.learner.select_action(self._state)
            if isinstance(self.learner, TabularLearner)
            else self.learner.select_action(self._obs)
        )
        self.iteration = 0
        self.cumulative_reward = 0.0
        self.collisions = 0
        self.respawns = 0

    # -- what was learnt, for the federated layer ---------------------------------------------
    @property
    def learner_kind(self) -> str:
        """``"tabular"`` (a Q-table over discrete states) or ``"function"`` (a model over the
        raw observation, parameters only)."""
        return self.learner.kind

    @property
    def params(self) -> np.ndarray:
        """What the learner learnt as one flat float64 vector (a new copy).

        Tabular: the Q-table in C order (layout ``[("q", (n_states, n_actions))]``);
        function learners: their arrays in :attr:`param_layout` order.
        """
        if isinstance(self.learner, TabularLearner):
            return self.learner.q.ravel().copy()
        return self.learner.get_params()

    @property
    def param_layout(self) -> Layout:
        """Names and shapes of the arrays :attr:`params` concatenates, in order (C order each)."""
        if isinstance(self.learner, TabularLearner):
            return [("q", tuple(self.learner.q.shape))]
        return self.learner.param_layout

    def set_params(self, vec: np.ndarray) -> None:
        """Replace what the learner learnt from a flat vector of :attr:`param_layout`.

        Tabular: the Q-table (as :meth:`set_q_table`). ``dqn``: the online and the target
        network (its Adam moments and replay buffer stay). Between two :meth:`step` calls.

        Raises
        ------
        ValueError
            Not 1-D, wrong length, or a non-finite entry.
        """
        if isinstance(self.learner, TabularLearner):
            q = validate_params(vec, self.param_layout)
            self.learner.set_table(q.reshape(self.learner.q.shape))
        else:
            self.learner.set_params(vec)

    @property
    def samples(self) -> int:
        """Environment transitions learnt from so far (the learner's update clock; the
        weight of this robot in a sample-weighted average)."""
        return int(self.learner.t)

    def _tabular_only(self, what: str) -> TabularLearner:
        if not isinstance(self.learner, TabularLearner):
            raise TypeError(
                f"{what}: learner '{self.config.algo}' is a function-approximation "
                f"learner without a Q-table; use params / set_params"
            )
        return self.learner

    @property
    def q_table(self) -> np.ndarray:
        """The live Q-table, float64, shape (n_states, n_actions). Writes go straight in.

        Raises
        ------
        TypeError
            A function-approximation learner (no table).
        """
        return self._tabular_only("q_table").q

    def set_q_table(self, table: np.ndarray) -> None:
        """Replace the Q-table (copied in place after checking shape and finiteness).

        Call it between two :meth:`step` calls. The action already chosen for the next step
        (from the old table) is kept; every later choice and update uses the new table.
        Visit counts are left as they are.

        Raises
        ------
        ValueError
            Wrong shape or a non-finite entry.
        TypeError
            A function-approximation learner (no table).
        """
        self._tabular_only("set_q_table").set_table(table)

    def read_table(self) -> np.ndarray:
        """An agent's read of the Q-table (the bridge's verb pair; README, "Words"): a copy of
        :attr:`q_table`."""
        return np.array(self.q_table)

    def write_table(self, table: np.ndarray, origin: Any = None) -> None:
        """An agent's write of the Q-table (the bridge's verb pair): :meth:`set_q_table`;
        ``origin``, where the write came from, is recorded by the caller."""
        self.set_q_table(table)

    @property
    def visits(self) -> np.ndarray:
        """Update counts per state-action pair, int64, shape (n_states, n_actions).

        Raises
        ------
        TypeError
            A function-approximation learner (no table).
        """
        return self._tabular_only("visits").visits

    @property
    def n_states(self) -> int:
        """Rows of the table."""
        return self.discretiser.n_states

    @property
    def action_names(self) -> list[str]:
        """Column names of the table."""
        return self.config.actions.names

    @property
    def pose(self) -> tuple[float, float, float]:
        """The robot's current pose: x, y (m), yaw (rad) (what the live view draws)."""
        return self.env.pose

    @property
    def sim_time(self) -> float:
        """Simulated seconds so far."""
        return self.iteration * self.config.sim.control_dt

    # -- the loop ----------------------------------------------------------------------------
    def step(self) -> StepMetrics:
        """One iteration: act, simulate 64 ms, sense, reward, update the table, choose next."""
        env = self.env
        state, action = self._state, self._action
        obs, reward, terminated, truncated, info = env.step(action)
        next_state = self.discretiser(obs)
        learnt, end = (
            (reward, terminated)
            if self.reward_shuffle is None
            else self.reward_shuffle(reward, terminated)
        )
        self.learned_reward, self.learned_terminal = learnt, end
        if isinstance(self.learner, TabularLearner):
            next_action = self.learner.learn(state, action, learnt, next_state, end)
        else:
            next_obs = np.array(obs, dtype=np.float64)
            next_action = self.learner.learn(self._obs, action, learnt, next_obs, end)
        if terminated or truncated:
            obs, _ = env.reset()
            next_state = self.discretiser(obs)
            next_action = (
                self.learner.select_action(next_state)
                if isinstance(self.learner, TabularLearner)
                else self.learner.select_action(np.array(obs, dtype=np.float64))
            )
            self.respawns += 1
        self._state, self._action = next_state, next_action
        if not self._tabular:
            self._obs = np.array(obs, dtype=np.float64)
        self.iteration += 1
        self.cumulative_reward += reward
        collided = bool(info["collision"])
        self.collisions += collided
        x, y, _ = info["pose"]
        return StepMetrics(
            iteration=self.iteration,
            q_sum=self._q_sum(),
            cumulative_reward=self.cumulative_reward,
            collisions=self.collisions,
            reward=reward,
            collided=collided,
            respawns=self.respawns,
            epsilon=self.learner.epsilon,
            state=state,
            action=action,
            x=x,
            y=y,
        )

    def _q_sum(self) -> float:
        if isinstance(self.learner, TabularLearner):
            return float(self.learner.q.sum())
        return float(self.learner.get_params().sum())

    def greedy_action(self, obs: np.ndarray) -> int:
        """The learnt greedy action for an observation (ties: lowest index), no exploration."""
        if isinstance(self.learner, TabularLearner):
            from dfrl.robots.td import greedy_action

            return greedy_action(self.learner.q[self.discretiser(obs)])
        return self.learner.greedy_action(np.asarray(obs, dtype=np.float64))

    def params_meta(self, **extra: Any) -> ParamsMeta:
        """Sidecar description of the current parameter vector."""
        c = self.config
        field_name = getattr(self.learner, "config_field", None)
        model = to_jsonable(getattr(c, field_name)) if field_name else {}
        return ParamsMeta(
            algo=c.algo,
            arena=self.env.arena.name,
            seed=c.seed,
            iterations=self.iteration,
            actions=self.action_names,
            layout=self.param_layout,
            model=model,
            extra=dict(extra),
        )

    def table_meta(self, **extra: Any) -> TableMeta:
        """Sidecar description of the current table."""
        c = self.config
        return TableMeta(
            algo=c.algo,
            arena=self.env.arena.name,
            seed=c.seed,
            iterations=self.iteration,
            actions=self.action_names,
            state=self.discretiser.describe(),
            extra=dict(extra),
        )

    def save_table(self, path: str | Path) -> Path:
        """Save the table, its sidecar and the visit counts (see :mod:`dfrl.robots.tables`)."""
        return save_table(path, self.q_table, self.table_meta(), visits=self.visits)

    def save_params(self, path: str | Path, **extra: Any) -> Path:
        """Save :attr:`params` and its sidecar (:func:`dfrl.robots.tables.save_params`)."""
        return save_params(path, self.params, self.params_meta(**extra))

    def close(self) -> None:
        """Release the simulation."""
        self.env.close()

    def __enter__(self) -> "Trainer":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclass(frozen=True)
class TrainingResult:
    """Outputs of :func:`train`.

    Attributes
    ----------
    metrics : np.ndarray, structured, shape (iterations,)
        One record per iteration with the fields of :class:`StepMetrics`.
    q_table : np.ndarray, shape (n_states, n_actions), or None
        None for a function-approximation learner.
    visits : np.ndarray, shape (n_states, n_actions), or None
        None for a function-approximation learner.
    wall_time : float
        Seconds spent stepping.
    output_dir : Path or None
    snapshots : dict of int to np.ndarray
        Copies of the Q-table (function learners: of the parameter vector) after every
        ``snapshot_every`` iterations (and the last one), by iteration; empty without
        ``snapshot_every``.
    params : np.ndarray, shape (n_params,)
        The final :attr:`Trainer.params` (tabular: the table, flattened).
    """

    metrics: np.ndarray
    q_table: np.ndarray | None
    visits: np.ndarray | None
    wall_time: float
    output_dir: Path | None
    snapshots: dict[int, np.ndarray] = field(default_factory=dict)
    params: np.ndarray = field(default_factory=lambda: np.zeros(0))


def train(
    config: TrainerConfig,
    output_dir: str | Path | None = None,
    progress: Callable[[int], None] | None = None,
    snapshot_every: int | None = None,
) -> TrainingResult:
    """Run ``config.iterations`` steps; optionally write the results into ``output_dir``.

    Writes ``config.json``, ``metrics.csv`` (one row per iteration, columns of
    :class:`StepMetrics`), ``q_table.npy`` + ``q_table.json`` + ``q_table.visits.npy``
    (function-approximation learners: ``params.npy`` + ``params.json`` instead,
    :func:`dfrl.robots.tables.save_params`), and with ``snapshot_every`` also
    ``snapshots.npz`` (one table or parameter vector per snapshot, key ``it<N>``).

    Parameters
    ----------
    config : TrainerConfig
    output_dir : str or Path, optional
    progress : callable, optional
        Called with the number of new iterations done (e.g. a tqdm ``update``).
    snapshot_every : int, optional
        Keep a copy of the table every so many iterations (for evaluation during learning).
    """
    if snapshot_every is not None and snapshot_every < 1:
        raise ValueError("snapshot_every must be >= 1")
    snapshots: dict[int, np.ndarray] = {}
    rows = np.empty(config.iterations, dtype=METRIC_DTYPE)
    with Trainer(config) as trainer:
        tabular = trainer.learner_kind == "tabular"
        t0 = time.perf_counter()
        chunk = max(1, config.iterations // 200)
        for i in range(config.iterations):
            rows[i] = trainer.step().as_row()
            if snapshot_every and ((i + 1) % snapshot_every == 0 or i + 1 == config.iterations):
                snapshots[i + 1] = trainer.q_table.copy() if tabular else trainer.params
            if progress is not None and (i + 1) % chunk == 0:
                progress(chunk)
        wall = time.perf_counter() - t0
        if progress is not None and config.iterations % chunk:
            progress(config.iterations % chunk)
        result = TrainingResult(
            metrics=rows,
            q_table=trainer.q_table.copy() if tabular else None,
            visits=trainer.visits.copy() if tabular else None,
            wall_time=wall,
            output_dir=Path(output_dir) if output_dir is not None else None,
            snapshots=snapshots,
            params=trainer.params,
        )
        if output_dir is not None:
            out = Path(output_dir)
            out.mkdir(parents=True, exist_ok=True)
            (out / "config.json").write_text(
                json.dumps(config.to_dict(), indent=2) + "\n", encoding="utf-8"
            )
            write_metrics_csv(out / "metrics.csv", rows)
            if tabular:
                save_table(
                    out / "q_table",
                    trainer.q_table,
                    trainer.table_meta(wall_time_s=round(wall, 3)),
                    visits=trainer.visits,
                )
            else:
                trainer.save_params(out / "params", wall_time_s=round(wall, 3))
            if snapshots:
                # numpy's stubs match a **dict of arrays against savez's allow_pickle: bool too
                np.savez(out / "snapshots.npz", **{f"it{k}": v for k, v in snapshots.items()})  # type: ignore[arg-type]
    return result
