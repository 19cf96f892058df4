"""Many tabular learners trained at once in the batched simulator.

:class:`BatchedTrainer` is :class:`dfrl.robots.training.Trainer` for ``n`` robots: one
:class:`~dfrl.robots.training.TrainerConfig` per robot (arena, seed, learner and its
hyper-parameters may differ; the simulation, actions, reward and discretisation are shared), the
same random streams per seed (``SeedSequence(seed).spawn``: the environment's, then the
learner's), the tables of all robots in one array ``q`` of shape (n, n_states, n_actions), and
:meth:`run` to advance every robot by many iterations in compiled code.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numba.typed import List

from dfrl.arenas.spec import ArenaError
from dfrl.robots.batched import tabular as T
from dfrl.robots.batched.shuffle import M_CAPACITY, M_MODE, MODES
from dfrl.robots.batched.world import BatchedWorld
from dfrl.robots.env import EnvConfig
from dfrl.robots.learners import validate_table
from dfrl.robots.reward_shuffle import ShuffleMode
from dfrl.robots.training import TrainerConfig

#: Name of the batched simulator (results record it beside ``"pybullet"``).
SIM_NAME = "batched"


class BatchError(ValueError):
    """Configurations the batched simulator cannot run together (the message says which)."""


def shared_env(
    configs: Sequence[TrainerConfig], learners: Mapping[str, int] | None = None
) -> EnvConfig:
    """The environment every config shares (arena aside).

    Raises
    ------
    BatchError
        No config, a learner without a table, or configs that differ in what the batch
        shares.
    """
    if not configs:
        raise BatchError("no robot to train")
    first = configs[0]
    accepted = T.ALGOS if learners is None else learners
    for k, c in enumerate(configs):
        if c.algo not in accepted:
            raise BatchError(
                f"robot {k}: learner '{c.algo}' is not batched here (batched "
                f"together: {sorted(accepted)}); use --sim pybullet"
            )
        for name in (
            "sim",
            "actions",
            "reward",
            "collision_response",
            "stuck_steps",
            "stuck_distance",
            "discretisation",
        ):
            if getattr(c, name) != getattr(first, name):
                raise BatchError(
                    f"robot {k}: '{name}' differs from robot 0's; one batch "
                    f"shares the simulation, actions, reward and states"
                )
    return env_part(first)


def env_part(config: TrainerConfig) -> EnvConfig:
    """The environment fields of a training configuration."""
    return config.env_config()


@dataclass(frozen=True)
class Record:
    """Per-step values of :meth:`BatchedTrainer.run` with ``record=True``, each of shape
    (n_robots, steps): the fields of :data:`dfrl.robots.batched.tabular.RECORD_FIELDS`."""

    reward: np.ndarray
    collided: np.ndarray
    q_sum: np.ndarray
    state: np.ndarray
    action: np.ndarray
    x: np.ndarray
    y: np.ndarray


class RobotBatch:
    """What every batch of learning robots holds: the world, each robot's generators (the
    environment's, the learner's and the learning control's streams of its seed, as
    :class:`~dfrl.robots.training.Trainer` spawns them), the exploration schedules, discounts,
    update counts and running statistics.

    Parameters
    ----------
    configs : sequence of TrainerConfig
        One per robot (see :func:`shared_env` for what they must share).
    motion_noise : bool
        As :class:`~dfrl.robots.batched.world.BatchedWorld`'s.
    learners : mapping of str to int
        The learners this batch accepts (name -> code).
    """

    def __init__(
        self, configs: Sequence[TrainerConfig], motion_noise: bool, learners: Mapping[str, int]
    ) -> None:
        env = shared_env(configs, learners)
        self.configs = list(configs)
        streams = [np.random.SeedSequence(c.seed).spawn(3) for c in configs]
        env_rngs = [np.random.default_rng(int(s[0].generate_state(1)[0])) for s in streams]
        self.world = BatchedWorld(
            env, [c.arena for c in configs], env_rngs, configs[0].discretisation, motion_noise
        )
        self.learner_rngs = List([np.random.default_rng(s[1]) for s in streams])
        # the learning control (reward_shuffle): a third stream, as Trainer's
        self.shuffle_rngs = List([np.random.default_rng(s[2]) for s in streams])
        width = max([c.reward_shuffle for c in configs] + [1])
        self.shuffle_buffer = np.zeros((len(configs), width, 2))
        self.shuffle_meta = np.zeros((len(configs), 4), dtype=np.int64)
        self.shuffle_meta[:, M_CAPACITY] = [c.reward_shuffle for c in configs]
        self.shuffle_meta[:, M_MODE] = [MODES[ShuffleMode(c.reward_shuffle_mode)] for c in configs]
        self.shuffle_total = np.zeros(len(configs))
        self.algo = np.array([learners[c.algo] for c in configs], dtype=np.int64)
        self.gamma = np.array([c.learner.gamma for c in configs])
        self.eps = np.array(
            [
                (
                    T.SCHEDULES[c.learner.epsilon.kind.value],
                    c.learner.epsilon.start,
                    c.learner.epsilon.end,
                    c.learner.epsilon.decay_steps,
                )
                for c in configs
            ],
            dtype=np.float64,
        )
        self.t = np.zeros(len(configs), dtype=np.int64)
        self.stats = np.zeros((len(configs), T.N_STATS))
        self.iteration = 0

    @property
    def n(self) -> int:
        """Number of robots."""
        return len(self.configs)

    def _arena_full(self, bad: int) -> None:
        if bad >= 0:
            raise ArenaError(
                f"{self.world.arenas[bad].source}: robot {bad} found no free pose "
                f"to respawn; the arena is too crowded"
            )

    @property
    def collisions(self) -> np.ndarray:
        """Collisions so far, per robot (int64)."""
        return self.stats[:, T.S_COLLISIONS].astype(np.int64)

    @property
    def respawns(self) -> np.ndarray:
        """Respawns so far, per robot (int64)."""
        return self.stats[:, T.S_RESPAWNS].astype(np.int64)

    @property
    def cumulative_reward(self) -> np.ndarray:
        """Reward earned so far, per robot."""
        return self.stats[:, T.S_REWARD].copy()


class BatchedTrainer(RobotBatch):
    """``n`` tabular robots learning, each as a :class:`~dfrl.robots.training.Trainer` would.

    Parameters
    ----------
    configs : sequence of TrainerConfig
        One per robot, Q-learning or SARSA (see :func:`shared_env` for what they must share).
    motion_noise : bool
        As :class:`~dfrl.robots.batched.world.BatchedWorld`'s.

    Attributes
    ----------
    q, visits : np.ndarray, shape (n, n_states, n_actions)
        Every robot's live table and update counts (writes go straight in).
    iteration : int
        Iterations done by every robot.
    """

    def __init__(self, configs: Sequence[TrainerConfig], motion_noise: bool = True) -> None:
        super().__init__(configs, motion_noise, T.ALGOS)
        n, w = len(configs), self.world
        n_states = configs[0].discretisation.n_states
        self.alpha = np.array([c.learner.alpha for c in configs])
        self.q = np.stack([np.full((n_states, w.n_actions), c.learner.initial_q) for c in configs])
        self.visits = np.zeros(self.q.shape, dtype=np.int64)
        self.stats[:, T.S_QSUM] = self.q.sum(axis=(1, 2))
        for i in range(n):
            w.start(i)
        self.state = w.states()
        self.action = np.array(
            [
                T.choose(self.q[i, self.state[i]], T.epsilon(self.eps[i], 0), self.learner_rngs[i])
                for i in range(n)
            ],
            dtype=np.int64,
        )

    def run(self, steps: int, record: bool = False) -> Record | None:
        """Advance every robot by ``steps`` iterations; with ``record``, their per-step values.

        Raises
        ------
        ArenaError
            A robot's arena has no free pose left for a respawn.
        """
        if steps < 0:
            raise ValueError(f"steps must be >= 0, got {steps}")
        rec = np.zeros((self.n, steps if record else 0, T.N_RECORD))
        w, p = self.world, self.world.packed
        bad = T.train(
            steps,
            self.algo,
            self.alpha,
            self.gamma,
            self.eps,
            self.q,
            self.visits,
            self.t,
            self.state,
            self.action,
            self.stats,
            rec,
            w.pose,
            w.prev,
            w.dist,
            w.trail,
            w.trail_len,
            w.trail_head,
            w.arena,
            p.first,
            p.count,
            p.half,
            p.boxes,
            w.angles,
            w.motion,
            w.groups,
            w.P,
            w.I,
            w.rngs,
            w.motion_rngs,
            self.learner_rngs,
            self.shuffle_buffer,
            self.shuffle_meta,
            self.shuffle_total,
            self.shuffle_rngs,
        )
        self._arena_full(bad)
        self.iteration += steps
        if not record:
            return None
        fields: dict[str, np.ndarray] = {
            name: rec[:, :, k] for k, name in enumerate(T.RECORD_FIELDS)
        }
        for name in ("state", "action"):
            fields[name] = fields[name].astype(np.int64)
        fields["collided"] = fields["collided"] > 0
        return Record(**fields)

    def set_table(self, i: int, table: np.ndarray) -> None:
        """Replace robot ``i``'s table (shape and finiteness checked), as
        :meth:`Trainer.set_q_table` does: the action already chosen is kept."""
        self.q[i] = validate_table(table, self.q.shape[1:])
        self.stats[i, T.S_QSUM] = float(self.q[i].sum())

    def set_tables(self, table: np.ndarray) -> None:
        """Give every robot the same table."""
        checked = validate_table(table, self.q.shape[1:])
        self.q[:] = checked
        self.stats[:, T.S_QSUM] = float(checked.sum())
