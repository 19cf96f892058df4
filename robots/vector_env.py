"""``dfrl/EPuck-v0`` as a Gymnasium vector environment backed by the batched simulator.

``gymnasium.make_vec("dfrl/EPuck-v0", num_envs=K, vectorization_mode="vector_entry_point",
arena="r4")`` returns an :class:`EPuckVectorEnv`: ``K`` sub-environments, each an e-puck alone
in its arena as in :class:`dfrl.robots.env.EPuckEnv`, stepped together by
:class:`dfrl.robots.batched.world.BatchedWorld` (compiled kernels, no pybullet in the loop).

The contract is :class:`gymnasium.vector.SyncVectorEnv`'s over ``K`` ``EPuckEnv`` (each wrapped
in the registered ``TimeLimit``):

* ``reset(seed=s)`` seeds sub-environment ``i`` with ``s + i`` (a list gives each its seed) and
  puts it at its arena's start pose, or at a random free pose drawn from the fresh generator
  when the start is random; without a seed, at a random free pose. Each sub-environment draws
  poses and sensor noise from its own generator, ``np.random.default_rng(seed_i)``, which is
  what ``EPuckEnv``'s ``np_random`` is after ``reset(seed=seed_i)``, and its motion's spread
  from that generator's first child (as :class:`BatchedWorld` spawns it).
* ``step(actions)``: termination = collision when ``collision_response`` is RESPAWN;
  truncation = stuck and not terminated, or ``max_episode_steps`` reached (as ``TimeLimit``).
* Autoreset ``NEXT_STEP`` (Gymnasium's default): the step after a sub-environment's episode
  ended resets it instead of stepping it, with reward 0, no termination, no truncation and the
  reset's observation and info.
* Infos are arrays with one row per sub-environment, each key with its ``_key`` mask.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from dfrl.arenas.spec import ArenaSpec, load_arena
from dfrl.robots.batched.world import BatchedWorld
from dfrl.robots.env import EnvConfig

ArenaLike = str | Path | ArenaSpec

#: Keys of the infos of :meth:`EPuckVectorEnv.reset` and :meth:`EPuckVectorEnv.step` (as
#: ``EPuckEnv``'s), each with its ``_key`` mask.
INFO_KEYS: tuple[str, ...] = ("collision", "stuck", "progress", "pose", "distances")


def _spec(arena: ArenaLike) -> ArenaSpec:
    return arena if isinstance(arena, ArenaSpec) else load_arena(arena)


class EPuckVectorEnv(VectorEnv):
    """``num_envs`` e-pucks, each alone in its arena, stepped together.

    Parameters
    ----------
    num_envs : int
        Number of sub-environments.
    arena : str or Path or ArenaSpec, or a sequence of them, optional
        Every sub-environment's arena (overrides ``config.arena``), or one per sub-environment.
    config : EnvConfig, optional
        Everything but the arena, shared by the sub-environments.
    render_mode : None
        The batched simulator draws nothing; only None is accepted.
    max_episode_steps : int, optional
        Truncate an episode after this many steps (``make_vec`` passes the registered 1,000, as
        ``make`` wraps ``EPuckEnv`` in ``TimeLimit``); None: no limit.
    **overrides
        Fields of :class:`EnvConfig` (e.g. ``stuck_steps=0``), as ``EPuckEnv`` takes them.

    Attributes
    ----------
    world : BatchedWorld
        The simulator; row ``i`` is sub-environment ``i``.
    """

    metadata: dict[str, Any] = {"render_modes": [], "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int = 1,
        arena: ArenaLike | Sequence[ArenaLike] | None = None,
        config: EnvConfig | None = None,
        render_mode: str | None = None,
        max_episode_steps: int | None = None,
        **overrides: Any,
    ) -> None:
        super().__init__()
        if (
            isinstance(num_envs, bool)
            or not isinstance(num_envs, (int, np.integer))
            or num_envs < 1
        ):
            raise ValueError(f"EPuckVectorEnv: num_envs must be an integer >= 1, got {num_envs!r}")
        if max_episode_steps is not None and max_episode_steps < 1:
            raise ValueError(
                f"EPuckVectorEnv: max_episode_steps must be >= 1 or None, got {max_episode_steps}"
            )
        if render_mode is not None:
            raise ValueError(
                f"EPuckVectorEnv: render_mode must be None (the batched simulator "
                f"draws nothing), got {render_mode!r}"
            )
        config = config or EnvConfig()
        if overrides:
            config = EnvConfig(**{**config.__dict__, **overrides})
        self.config = config
        self.num_envs = int(num_envs)
        self.render_mode = None
        self.max_episode_steps = max_episode_steps
        if arena is None or isinstance(arena, (str, Path, ArenaSpec)):
            specs = [_spec(arena if arena is not None else config.arena)] * self.num_envs
        else:
            specs = [_spec(a) for a in arena]
            if len(specs) != self.num_envs:
                raise ValueError(
                    f"EPuckVectorEnv: {len(specs)} arenas for {self.num_envs} "
                    f"sub-environments; give one arena or one per sub-environment"
                )
        # the world keeps these generator objects: reseeding one sets its state in place
        self._rngs = [np.random.default_rng() for _ in range(self.num_envs)]
        self.world = BatchedWorld(config, specs, self._rngs)
        self.single_observation_space = spaces.Box(
            0.0, 1.0, shape=(self.world.n_sensors,), dtype=np.float32
        )
        self.single_action_space = spaces.Discrete(self.world.n_actions)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self._elapsed = np.zeros(self.num_envs, dtype=np.int64)
        self._autoreset = np.zeros(self.num_envs, dtype=np.bool_)

    @property
    def arenas(self) -> list[ArenaSpec]:
        """Each sub-environment's arena."""
        return self.world.arenas

    @property
    def pose(self) -> np.ndarray:
        """Every robot's pose after the last ``reset``/``step``, shape (num_envs, 3): x, y (m)
        and yaw (rad); a copy."""
        return self.world.pose.copy()

    # -- Gymnasium API ---------------------------------------------------------------------
    def reset(
        self,
        *,
        seed: int | Sequence[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Reset the sub-environments and return every observation, shape (num_envs, 8).

        Parameters
        ----------
        seed : int or sequence of (int or None), optional
            ``s``: sub-environment ``i`` gets ``s + i``; a sequence: one seed each.
        options : dict, optional
            ``"reset_mask"``: a bool array, shape (num_envs,), of the sub-environments to reset
            (the others keep their state and observation; infos mask them out).
            ``"pose"``: ``(x, y, yaw)`` for all, or shape (num_envs, 3), forces the poses.

        Raises
        ------
        ValueError
            Seeds, mask or poses of the wrong length or type, or an unknown option.
        """
        n = self.num_envs
        seeds = self._seeds(seed)
        options = dict(options or {})
        mask = self._reset_mask(options.pop("reset_mask", None))
        poses = self._poses(options.pop("pose", None))
        if options:
            raise ValueError(
                f"EPuckVectorEnv.reset: unknown options {sorted(options)} (known: reset_mask, pose)"
            )
        for index in np.flatnonzero(mask):
            i = int(index)
            seed_i = seeds[i]
            if seed_i is not None:
                self._seed(i, seed_i)
            if poses is not None:
                self.world.place(i, (poses[i, 0], poses[i, 1], poses[i, 2]))
            elif seeds[i] is not None:
                self.world.start(i)
            else:
                self.world.respawn(i)
        self._elapsed[mask] = 0
        self._autoreset[mask] = False
        zeros = np.zeros(n, dtype=np.bool_)
        return self.world.observations(), self._infos(zeros, zeros, np.zeros(n), mask)

    def step(
        self, actions: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """One control step of every sub-environment (or its autoreset).

        Parameters
        ----------
        actions : array of int, shape (num_envs,)
            Each sub-environment's action (ignored for those being reset).

        Returns
        -------
        observations : np.ndarray, shape (num_envs, 8), float32
        rewards : np.ndarray, shape (num_envs,), float64
        terminations, truncations : np.ndarray, shape (num_envs,), bool
        infos : dict
            ``collision``, ``stuck`` (bool), ``progress`` (float64), ``pose`` (num_envs, 3),
            ``distances`` (num_envs, 8, m), each with its ``_key`` mask (all True).

        Raises
        ------
        ValueError
            Actions not in :attr:`action_space`.
        """
        acts = np.asarray(actions)
        if (
            acts.shape != (self.num_envs,)
            or not np.issubdtype(acts.dtype, np.integer)
            or not self.action_space.contains(acts.astype(np.int64))
        ):
            raise ValueError(
                f"EPuckVectorEnv.step: actions must be {self.num_envs} integers in "
                f"0..{self.world.n_actions - 1}, got {actions!r}"
            )
        resetting = np.flatnonzero(self._autoreset)
        # the kernel steps every robot: a robot being reset is stepped too and its step thrown
        # away; its generators are put back first, so the reset draws what EPuckEnv.reset()
        # would and the step leaves no trace
        saved = [self._states(int(i)) for i in resetting]
        result = self.world.step(acts)
        rewards = result.reward
        collision, stuck, progress = result.collision, result.stuck, result.progress
        terminated = collision & self.world.respawn_on_collision
        self._elapsed += 1
        truncated = stuck & ~terminated
        if self.max_episode_steps is not None:
            truncated |= self._elapsed >= self.max_episode_steps
        for i, states in zip(resetting, saved):
            self._set_states(int(i), states)
            self.world.respawn(int(i))
        if resetting.size:
            for a in (rewards, progress):
                a[resetting] = 0.0
            for a in (terminated, truncated, collision, stuck):
                a[resetting] = False
            self._elapsed[resetting] = 0
        self._autoreset = terminated | truncated
        infos = self._infos(collision, stuck, progress, np.ones(self.num_envs, dtype=np.bool_))
        return self.world.observations(), rewards, terminated, truncated, infos

    def render(self) -> None:
        """The batched simulator draws nothing."""
        return None

    # -- helpers ---------------------------------------------------------------------------
    def _generators(self, i: int) -> tuple[np.random.Generator, np.random.Generator]:
        """Robot ``i``'s generator (poses, sensor noise) and its motion's (the world's child of
        it)."""
        return self._rngs[i], self.world.motion_rngs[i]

    def _seed(self, i: int, seed: int) -> None:
        """Robot ``i``'s generators as a world built with ``default_rng(seed)`` has them."""
        fresh = np.random.default_rng(seed)
        motion = fresh.spawn(1)[0]  # as BatchedWorld spawns it, before any draw
        self._set_states(i, (fresh.bit_generator.state, motion.bit_generator.state))

    def _states(self, i: int) -> tuple[Mapping[str, Any], ...]:
        return tuple(g.bit_generator.state for g in self._generators(i))

    def _set_states(self, i: int, states: tuple[Mapping[str, Any], ...]) -> None:
        for g, state in zip(self._generators(i), states):
            g.bit_generator.state = state

    def _seeds(self, seed: int | Sequence[int | None] | None) -> list[int | None]:
        n = self.num_envs
        if seed is None:
            return [None] * n
        if isinstance(seed, (int, np.integer)) and not isinstance(seed, bool):
            return [int(seed) + i for i in range(n)]
        if isinstance(seed, bool):
            raise TypeError(f"EPuckVectorEnv.reset: a seed is an int, got {seed!r}")
        seeds = list(seed)
        if len(seeds) != n:
            raise ValueError(f"EPuckVectorEnv.reset: {len(seeds)} seeds for {n} sub-environments")
        return [None if s is None else int(s) for s in seeds]

    def _poses(self, poses: Any) -> np.ndarray | None:
        if poses is None:
            return None
        n = self.num_envs
        array = np.asarray(poses, dtype=np.float64)
        if array.shape not in ((3,), (n, 3)) or not np.isfinite(array).all():
            raise ValueError(
                f"EPuckVectorEnv.reset: options['pose'] must be finite (x, y, yaw) "
                f"or of shape ({n}, 3), got shape {array.shape}"
            )
        return np.broadcast_to(array, (n, 3))

    def _reset_mask(self, mask: Any) -> np.ndarray:
        n = self.num_envs
        if mask is None:
            return np.ones(n, dtype=np.bool_)
        if (
            not isinstance(mask, np.ndarray)
            or mask.dtype != np.bool_
            or mask.shape != (n,)
            or not mask.any()
        ):
            raise ValueError(
                f"EPuckVectorEnv.reset: options['reset_mask'] must be a bool "
                f"array of shape ({n},) with at least one True"
            )
        return mask

    def _infos(
        self, collision: np.ndarray, stuck: np.ndarray, progress: np.ndarray, mask: np.ndarray
    ) -> dict[str, Any]:
        values = {
            "collision": collision,
            "stuck": stuck,
            "progress": progress,
            "pose": self.world.pose.copy(),
            "distances": self.world.dist.copy(),
        }
        infos: dict[str, Any] = {}
        for key in INFO_KEYS:
            value = values[key]
            if not mask.all():
                value = np.where(
                    mask.reshape(-1, *[1] * (value.ndim - 1)), value, np.zeros_like(value)
                )
            infos[key] = value
            infos[f"_{key}"] = mask.copy()
        return infos
