"""Many e-pucks, each alone in its own arena, stepped together by compiled kernels.

:class:`BatchedWorld` is the batched counterpart of :class:`dfrl.robots.env.EPuckEnv` for
``n`` robots at once: the same arena files, robot geometry, IR response and noise, actions,
reward, collision and stuck rules, observation and discretisation, on arrays (one row per
robot). Robots do not see each other (as on the federation's nodes, each robot has its arena to
itself). The motion of a step comes from :func:`dfrl.robots.batched.motion.measured_motion`;
sensing and contact are geometry (rays and signed distances against the arena's boxes).

Each robot draws from its own ``numpy.random.Generator`` (``rngs[i]``), as ``EPuckEnv`` draws from
its ``np_random``: the same seed gives the same run whatever else is in the batch.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba.typed import List

from dfrl.arenas.spec import ArenaError, ArenaSpec, load_arena
from dfrl.robots.batched import kernels as K
from dfrl.robots.batched.motion import measured_motion
from dfrl.robots.batched.obstacles import PackedArenas, pack_arenas
from dfrl.robots.env import CollisionResponse, EnvConfig
from dfrl.robots.state import DiscretisationConfig

#: Largest end-of-step clearance (m) at which pybullet reports the body touching a wall: driving
#: into R4's walls at 40 headings, the first touching step ended at most 0.7 mm away and the
#: last free one at least 0.9 mm (robots/README.md, "The batched simulator").
CONTACT_MARGIN: float = 0.0008


def float_params(config: EnvConfig) -> np.ndarray:
    """The ``P_*`` vector of the kernels for an environment configuration."""
    rc, rw = config.sim.robot, config.reward
    p = np.zeros(K.N_FLOAT_PARAMS)
    p[K.P_BODY_RADIUS] = rc.body_radius
    p[K.P_SENSOR_RANGE] = rc.sensor_range
    p[K.P_RAY_START] = rc.axle_length / 2 + rc.wheel_width / 2 + 1e-3  # as EPuck's rays
    p[K.P_NOISE_STD] = rc.sensor_noise_std
    p[K.P_STEP_LENGTH] = rc.max_linear_speed * config.sim.control_dt
    p[K.P_RESPAWN_CLEARANCE] = rc.body_radius + 0.03  # as EPuckEnv's
    p[K.P_STUCK_DISTANCE] = config.stuck_distance
    p[K.P_CONTACT] = CONTACT_MARGIN
    p[K.P_ALIVE] = rw.alive_bonus
    p[K.P_FORWARD] = rw.forward_weight
    p[K.P_NEAR_THRESHOLD] = rw.near_threshold
    p[K.P_NEAR_PENALTY] = rw.near_penalty
    p[K.P_COLLISION_PENALTY] = rw.collision_penalty
    return p


def int_params(config: EnvConfig, discretisation: DiscretisationConfig) -> np.ndarray:
    """The ``I_*`` vector of the kernels."""
    i = np.zeros(K.N_INT_PARAMS, dtype=np.int64)
    i[K.I_STUCK_STEPS] = config.stuck_steps
    i[K.I_RESPAWN] = 1 if config.collision_response is CollisionResponse.RESPAWN else 0
    i[K.I_LEVELS] = discretisation.levels
    return i


def group_table(discretisation: DiscretisationConfig) -> np.ndarray:
    """The discretisation's sensor groups, padded with -1, shape (n_groups, largest)."""
    groups = discretisation.grouping.groups
    out = np.full((len(groups), max(len(g) for g in groups)), -1, dtype=np.int64)
    for g, members in enumerate(groups):
        out[g, : len(members)] = members
    return out


@dataclass(frozen=True)
class StepResult:
    """What one :meth:`BatchedWorld.step` returns, one entry per robot."""

    reward: np.ndarray
    collision: np.ndarray
    stuck: np.ndarray
    progress: np.ndarray


class BatchedWorld:
    """``n`` robots in their arenas, with their generators.

    Parameters
    ----------
    config : EnvConfig
        Everything but the arena is shared by the robots (``config.arena`` is unused).
    arenas : sequence of str or ArenaSpec
        Each robot's arena (names, paths or specs; repeated arenas are packed once).
    rngs : sequence of numpy.random.Generator
        Each robot's environment generator (poses, noise).
    discretisation : DiscretisationConfig, optional
        For :meth:`states`.
    motion_noise : bool
        Draw each step's motion around its mean with pybullet's measured spread (default);
        False replays the means (a deterministic robot, for the fidelity report's ablation).
    """

    def __init__(
        self,
        config: EnvConfig,
        arenas: Sequence[str | ArenaSpec],
        rngs: Sequence[np.random.Generator],
        discretisation: DiscretisationConfig | None = None,
        motion_noise: bool = True,
    ) -> None:
        if len(arenas) != len(rngs) or not arenas:
            raise ValueError(
                f"one generator per robot: {len(arenas)} arenas, {len(rngs)} generators"
            )
        self.config = config
        specs: dict[str, ArenaSpec] = {}
        parsed: dict[str, ArenaSpec] = {}  # each name or path read once
        index: list[int] = []
        for a in arenas:
            if isinstance(a, ArenaSpec):
                spec = a
            else:
                if str(a) not in parsed:
                    parsed[str(a)] = load_arena(a)
                spec = parsed[str(a)]
            key = f"{spec.source}|{spec.name}"
            if key not in specs:
                specs[key] = spec
            index.append(list(specs).index(key))
        rc = config.sim.robot
        self.packed: PackedArenas = pack_arenas(list(specs.values()), rc.sensor_height)
        self.arena = np.asarray(index, dtype=np.int64)
        self.n = len(arenas)
        self.n_sensors = len(rc.sensor_angles)
        self.angles = np.asarray(rc.sensor_angles, dtype=np.float64)
        measured = measured_motion(config.sim, config.actions)
        spread = measured.std if motion_noise else np.zeros_like(measured.std)
        #: per (previous action + 1, action): mean (forward, left, turn), then their spread
        self.motion = np.ascontiguousarray(np.concatenate([measured.mean, spread], axis=2))
        self.n_actions = self.motion.shape[1]
        self.P = float_params(config)
        self.discretisation = discretisation or DiscretisationConfig()
        self.I = int_params(config, self.discretisation)
        self.groups = group_table(self.discretisation)
        self.rngs = List(rngs)
        #: the motion's spread draws from a child of each robot's generator, so that the
        #: robot's own stream (start and respawn poses, sensor noise) is drawn as in pybullet
        self.motion_rngs = List([r.spawn(1)[0] for r in rngs])
        self.pose = np.zeros((self.n, 3))
        self.prev = np.zeros(self.n, dtype=np.int64)
        self.dist = np.full((self.n, self.n_sensors), rc.sensor_range)
        self.trail = np.zeros((self.n, config.stuck_steps + 1, 2))
        self.trail_len = np.zeros(self.n, dtype=np.int64)
        self.trail_head = np.zeros(self.n, dtype=np.int64)
        self._out = np.zeros((self.n, 4))

    @property
    def arenas(self) -> list[ArenaSpec]:
        """Each robot's arena."""
        return [self.packed.arenas[a] for a in self.arena]

    def _rows(self, i: int) -> tuple[int, int]:
        a = self.arena[i]
        return int(self.packed.first[a]), int(self.packed.first[a] + self.packed.count[a])

    def place(self, i: int, pose: tuple[float, float, float]) -> None:
        """Put robot ``i`` at rest at ``pose`` and read its sensors."""
        lo, hi = self._rows(i)
        K.place(
            i,
            float(pose[0]),
            float(pose[1]),
            float(pose[2]),
            self.pose,
            self.prev,
            self.dist,
            self.trail,
            self.trail_len,
            self.trail_head,
            self.packed.boxes,
            lo,
            hi,
            self.angles,
            self.P,
            self.rngs[i],
        )

    def start(self, i: int) -> None:
        """A seeded reset of robot ``i``: its arena's start pose, or a random free pose."""
        s = self.packed.start[self.arena[i]]
        if s[0] == 0.0:
            self.place(i, (s[1], s[2], s[3]))
        else:
            self.respawn(i)

    def respawn(self, i: int) -> None:
        """A reset without a seed: a random free pose.

        Raises
        ------
        ArenaError
            No free pose found (the arena is too crowded).
        """
        p = self.packed
        if not K.respawn(
            i,
            self.pose,
            self.prev,
            self.dist,
            self.trail,
            self.trail_len,
            self.trail_head,
            self.arena,
            p.first,
            p.count,
            p.half,
            p.boxes,
            self.angles,
            self.P,
            self.rngs[i],
        ):
            arena = p.arenas[self.arena[i]]
            raise ArenaError(
                f"{arena.source}: no free pose with clearance "
                f"{self.P[K.P_RESPAWN_CLEARANCE]} m found in {K.MAX_TRIES} tries; "
                f"the arena is too crowded"
            )

    def step(self, actions: np.ndarray) -> StepResult:
        """Every robot takes its action for one control step."""
        acts = np.asarray(actions, dtype=np.int64)
        if acts.shape != (self.n,) or acts.min() < 0 or acts.max() >= self.n_actions:
            raise ValueError(f"actions must be {self.n} integers in 0..{self.n_actions - 1}")
        p = self.packed
        K.step_all(
            acts,
            self.pose,
            self.prev,
            self.dist,
            self.trail,
            self.trail_len,
            self.trail_head,
            self.arena,
            p.first,
            p.count,
            p.boxes,
            self.angles,
            self.motion,
            self.P,
            self.I,
            self.rngs,
            self.motion_rngs,
            self._out,
        )
        o = self._out
        return StepResult(
            reward=o[:, 0].copy(), collision=o[:, 1] > 0, stuck=o[:, 2] > 0, progress=o[:, 3].copy()
        )

    def wander(self, steps: int, policy_rngs: Sequence[np.random.Generator]) -> None:
        """``steps`` steps of every robot with uniform random actions (robot ``i``'s drawn
        from ``policy_rngs[i]``), in one compiled loop; a robot whose episode ends respawns.

        Raises
        ------
        ArenaError
            A robot's arena has no free pose left.
        """
        if len(policy_rngs) != self.n:
            raise ValueError(
                f"one policy generator per robot: {self.n} robots, {len(policy_rngs)} generators"
            )
        p = self.packed
        bad = K.wander(
            steps,
            self.n_actions,
            self.pose,
            self.prev,
            self.dist,
            self.trail,
            self.trail_len,
            self.trail_head,
            self.arena,
            p.first,
            p.count,
            p.half,
            p.boxes,
            self.angles,
            self.motion,
            self.P,
            self.I,
            self.rngs,
            self.motion_rngs,
            List(policy_rngs),
        )
        if bad >= 0:
            raise ArenaError(f"{self.arenas[bad].source}: robot {bad} found no free pose")

    def observations(self) -> np.ndarray:
        """The IR proximities of every robot, shape (n, n_sensors), float32."""
        return (1.0 - self.dist / self.P[K.P_SENSOR_RANGE]).astype(np.float32)

    def states(self) -> np.ndarray:
        """Each robot's tabular state, shape (n,), int64."""
        rng_ = self.P[K.P_SENSOR_RANGE]
        levels = int(self.I[K.I_LEVELS])
        return np.array(
            [K.discretise(self.dist[i], rng_, self.groups, levels) for i in range(self.n)],
            dtype=np.int64,
        )

    @property
    def respawn_on_collision(self) -> bool:
        """True when a collision ends the episode (``CollisionResponse.RESPAWN``)."""
        return bool(self.I[K.I_RESPAWN])
