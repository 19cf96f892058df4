"""The e-puck in an arena as a Gymnasium environment (``dfrl/EPuck-v0``).

Observation: the 8 IR proximities ``1 - d / sensor_range`` in ``[0, 1]`` (float32, 1 = touching).
Actions: ``Discrete(n)`` over an :class:`ActionSet` (default: forward, turn left, turn right).
Reward: see :class:`RewardConfig` and ``robots/README.md``.
Termination: a collision (contact with a wall or a block) ends the episode when
``collision_response`` is RESPAWN (default); the next ``reset()`` puts the robot at a random
free pose. Truncation: the robot has moved less than ``stuck_distance`` during the last
``stuck_steps`` control steps (e.g. wedged, or spinning on the spot).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from dfrl.arenas.spec import ArenaSpec, load_arena
from dfrl.robots.world import SimConfig, World


class ActionSet(str, Enum):
    """Named sets of wheel commands; each action is ``(name, left, right)`` as fractions of
    the maximal wheel speed."""

    BASIC = "basic"  #: forward, turn left on the spot, turn right on the spot
    EXTENDED = "extended"  #: BASIC plus a gentle left and a gentle right arc

    @property
    def actions(self) -> tuple[tuple[str, float, float], ...]:
        """The ``(name, left_fraction, right_fraction)`` of each action, by index."""
        basic = (("forward", 1.0, 1.0), ("left", -0.5, 0.5), ("right", 0.5, -0.5))
        if self is ActionSet.BASIC:
            return basic
        return basic + (("arc_left", 0.5, 1.0), ("arc_right", 1.0, 0.5))

    @property
    def names(self) -> list[str]:
        """Action names by index."""
        return [a[0] for a in self.actions]


class CollisionResponse(str, Enum):
    """What a collision does besides being counted and penalised."""

    RESPAWN = "respawn"  #: terminate the episode; the next reset draws a random free pose
    CONTINUE = "continue"  #: keep going from where the robot is (it must turn away itself)


@dataclass(frozen=True)
class RewardConfig:
    """Reward for obstacle avoidance, computed every control step.

    ``r = alive_bonus + forward_weight * v / v_max
          - near_penalty * max(0, (p_max - near_threshold) / (1 - near_threshold))
          - collision_penalty * [collision]``

    where ``v`` is the measured speed along the heading during the step (clipped to
    ``[-v_max, v_max]``; pushing against a wall earns nothing), ``v_max`` the top speed, and
    ``p_max`` the largest IR proximity. The alive bonus is what a collision (which ends the
    episode) takes away; driving ahead freely is worth twice as much as turning on the spot.

    Attributes
    ----------
    alive_bonus : float
        Reward for every step, whatever the action.
    forward_weight : float
        Reward for driving straight ahead at top speed for one step.
    near_threshold : float
        Proximity in ``[0, 1)`` above which the near-contact penalty starts
        (0.5 = half the sensor range, 3 cm by default).
    near_penalty : float
        Penalty when an obstacle touches a sensor (proximity 1); linear in between.
    collision_penalty : float
        Penalty for a step that ends in contact with a wall or a block.
    """

    alive_bonus: float = 0.3
    forward_weight: float = 0.7
    near_threshold: float = 0.5
    near_penalty: float = 1.0
    collision_penalty: float = 10.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.near_threshold < 1.0:
            raise ValueError("RewardConfig.near_threshold must be in [0, 1)")


@dataclass(frozen=True)
class EnvConfig:
    """Everything that defines an :class:`EPuckEnv`.

    Attributes
    ----------
    arena : str
        Built-in arena name (``"r1"`` ... ``"r5"``) or path of an arena JSON file.
    sim : SimConfig
        Control and physics rates, solver, robot parameters, DIRECT/GUI.
    actions : ActionSet
        The discrete actions.
    reward : RewardConfig
        Reward shaping.
    collision_response : CollisionResponse
        RESPAWN (default) or CONTINUE.
    stuck_steps : int
        Window (control steps) of the stuck detector; 0 disables it.
    stuck_distance : float
        Minimal displacement over the window (m) not to be considered stuck.
    """

    arena: str = "r4"
    sim: SimConfig = field(default_factory=SimConfig)
    actions: ActionSet = ActionSet.BASIC
    reward: RewardConfig = field(default_factory=RewardConfig)
    collision_response: CollisionResponse = CollisionResponse.RESPAWN
    stuck_steps: int = 150
    stuck_distance: float = 0.03

    def __post_init__(self) -> None:
        object.__setattr__(self, "actions", ActionSet(self.actions))
        object.__setattr__(self, "collision_response", CollisionResponse(self.collision_response))
        if self.stuck_steps < 0:
            raise ValueError("EnvConfig.stuck_steps must be >= 0")


class EPuckEnv(gym.Env):
    """An e-puck learning obstacle avoidance in an arena.

    Parameters
    ----------
    arena : str or Path or ArenaSpec, optional
        Overrides ``config.arena``: a built-in name like ``"r4"``, a file path, or a spec.
    config : EnvConfig, optional
        Full configuration.
    render_mode : {"rgb_array"} or None
        "rgb_array" returns a top view (headless). For a GUI window pass
        ``sim=SimConfig(connection="gui")``.
    **overrides
        Fields of :class:`EnvConfig` (e.g. ``stuck_steps=0``), for ``gym.make`` convenience.
    """

    action_space: spaces.Discrete
    observation_space: spaces.Box

    #: "rgb_array" renders a top view headless. The pybullet GUI window is opened with
    #: ``sim=SimConfig(connection="gui")`` rather than a "human" render mode, so that headless
    #: machines (and ``check_env``, which tries every listed mode) never need a display.
    metadata = {"render_modes": ["rgb_array"], "render_fps": 15}

    def __init__(
        self,
        arena: str | Path | ArenaSpec | None = None,
        config: EnvConfig | None = None,
        render_mode: str | None = None,
        **overrides: Any,
    ) -> None:
        super().__init__()
        config = config or EnvConfig()
        if overrides:
            config = EnvConfig(**{**config.__dict__, **overrides})
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be one of {self.metadata['render_modes']}")
        self.config = config
        self.render_mode = render_mode
        if isinstance(arena, ArenaSpec):
            self.arena = arena
        else:
            self.arena = load_arena(arena if arena is not None else config.arena)
        self.world = World(self.arena, config.sim)
        self.robot = self.world.robot
        rc = config.sim.robot
        self._actions = config.actions.actions
        vmax = rc.max_wheel_speed
        self._wheel_cmds = [(vmax * a[1], vmax * a[2]) for a in self._actions]
        self._v_max = rc.max_linear_speed
        self._clearance = rc.body_radius + 0.03
        self.action_space = spaces.Discrete(len(self._actions))
        self.observation_space = spaces.Box(
            0.0, 1.0, shape=(self.robot.n_sensors,), dtype=np.float32
        )
        self._pose: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._trail: deque[tuple[float, float]] = deque(maxlen=max(1, config.stuck_steps + 1))
        self._distances = np.full(self.robot.n_sensors, rc.sensor_range)
        self.sim_steps = 0

    @property
    def pose(self) -> tuple[float, float, float]:
        """The robot's pose after the last ``reset``/``step``: x, y (m) and yaw (rad)."""
        return self._pose

    # -- Gymnasium API ---------------------------------------------------------------------
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Place the robot and return the first observation.

        With a ``seed`` the robot goes to the arena's start pose (or a random free pose drawn
        from the freshly seeded generator when the arena's start is random). Without a seed
        (a respawn) it goes to a random free pose. ``options={"pose": (x, y, yaw)}`` forces a
        pose.
        """
        super().reset(seed=seed)
        options = options or {}
        if seed is not None:
            # same seed, same world: a rebuilt client holds no contact state from before
            self.world.rebuild()
            self.robot = self.world.robot
        pose: tuple[float, float, float]
        if "pose" in options:
            x, y, yaw = (float(v) for v in options["pose"])
            pose = (x, y, yaw)
        elif seed is not None and not self.arena.start.random:
            assert self.arena.start.pose is not None, "a start that is not random has a pose"
            pose = self.arena.start.pose
        else:
            pose = self.arena.sample_free_pose(self.np_random, self._clearance)
        self.world.place_robot(*pose)
        self._pose = pose
        self._trail.clear()
        self._trail.append((pose[0], pose[1]))
        obs = self._observe()
        return obs, self._info(collision=False, stuck=False, progress=0.0)

    def step(self, action: int) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """One control step: command the wheels, run the physics, sense, reward."""
        left, right = self._wheel_cmds[int(action)]
        self.world.step(left, right)
        self.sim_steps += 1
        x0, y0, yaw0 = self._pose
        pose = self.robot.pose()
        self._pose = pose
        heading = yaw0 + 0.5 * math.remainder(pose[2] - yaw0, 2 * math.pi)
        progress = ((pose[0] - x0) * math.cos(heading) + (pose[1] - y0) * math.sin(heading)) / (
            self._v_max * self.config.sim.control_dt
        )
        collision = self.world.in_collision()
        obs = self._observe()
        stuck = self._stuck(pose)
        reward = self._reward(obs, progress, collision)
        terminated = self._terminated(collision)
        return (
            obs,
            reward,
            terminated,
            stuck and not terminated,
            self._info(collision, stuck, progress),
        )

    def render(self) -> np.ndarray | None:
        """Top view as an RGB array, shape (480, 480, 3), uint8 (``rgb_array`` mode)."""
        if self.render_mode == "rgb_array":
            return self.world.render_top()
        return None

    def close(self) -> None:
        """Release the pybullet client."""
        world = getattr(self, "world", None)
        if world is not None:
            world.close()

    # -- hooks -----------------------------------------------------------------------------
    def _reward(self, obs: np.ndarray, progress: float, collision: bool) -> float:
        rc = self.config.reward
        r = rc.alive_bonus + rc.forward_weight * min(max(progress, -1.0), 1.0)
        p_max = float(obs.max())
        if p_max > rc.near_threshold:
            r -= rc.near_penalty * (p_max - rc.near_threshold) / (1.0 - rc.near_threshold)
        if collision:
            r -= rc.collision_penalty
        return float(r)

    def _terminated(self, collision: bool) -> bool:
        return collision and self.config.collision_response is CollisionResponse.RESPAWN

    # -- helpers ---------------------------------------------------------------------------
    def _observe(self) -> np.ndarray:
        self._distances = self.robot.sense(self.np_random)
        return self.robot.proximity(self._distances).astype(np.float32)

    def _stuck(self, pose: tuple[float, float, float]) -> bool:
        n = self.config.stuck_steps
        self._trail.append((pose[0], pose[1]))
        if n == 0 or len(self._trail) <= n:
            return False
        x0, y0 = self._trail[0]
        return math.hypot(pose[0] - x0, pose[1] - y0) < self.config.stuck_distance

    def _info(self, collision: bool, stuck: bool, progress: float) -> dict[str, Any]:
        return {
            "collision": collision,
            "stuck": stuck,
            "progress": progress,
            "pose": self._pose,
            "distances": self._distances.copy(),
        }
