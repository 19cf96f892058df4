"""A pybullet client holding one arena and one e-puck, stepped at the control rate."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import Enum

import numpy as np

from dfrl.arenas.builder import ArenaBodies, build_arena
from dfrl.arenas.pybullet_quiet import load as _load_pybullet
from dfrl.arenas.spec import ArenaSpec
from dfrl.robots.epuck import EPuck, EPuckConfig

p = _load_pybullet()  # pybullet, without its build-time banner


class ConnectionMode(str, Enum):
    """How to connect to pybullet."""

    DIRECT = "direct"  #: headless, deterministic, fastest (default)
    GUI = "gui"  #: an OpenGL window (needs a display)


@dataclass(frozen=True)
class SimConfig:
    """Timing and solver settings of the simulation.

    Attributes
    ----------
    control_dt : float
        Simulated time of one control step (s); 64 ms as on the paper's robots.
    physics_dt : float
        Simulated time of one physics step (s). ``control_dt`` must be an integer multiple.
    solver_iterations : int
        Constraint solver iterations per physics step.
    connection : ConnectionMode
        DIRECT (headless) or GUI.
    robot : EPuckConfig
        The robot's parameters.
    """

    control_dt: float = 0.064
    physics_dt: float = 0.008
    solver_iterations: int = 10
    connection: ConnectionMode = ConnectionMode.DIRECT
    robot: EPuckConfig = field(default_factory=EPuckConfig)

    def __post_init__(self) -> None:
        object.__setattr__(self, "connection", ConnectionMode(self.connection))
        if not (self.control_dt > 0 and self.physics_dt > 0):
            raise ValueError(
                f"control_dt and physics_dt must be positive, "
                f"got {self.control_dt}, {self.physics_dt}"
            )
        if self.solver_iterations < 1:
            raise ValueError("solver_iterations must be >= 1")
        _ = self.substeps  # validates the ratio

    @property
    def substeps(self) -> int:
        """Physics steps per control step.

        Raises
        ------
        ValueError
            If ``control_dt`` is not an integer multiple of ``physics_dt``.
        """
        ratio = self.control_dt / self.physics_dt
        n = round(ratio)
        if n < 1 or abs(ratio - n) > 1e-9 * max(1.0, ratio):
            raise ValueError(
                f"control_dt ({self.control_dt} s) must be an integer multiple of physics_dt "
                f"({self.physics_dt} s); the ratio is {ratio:.6g}"
            )
        return n


class World:
    """One pybullet client with an arena and a robot.

    Parameters
    ----------
    arena : ArenaSpec
        The arena to build.
    config : SimConfig
        Timing, solver and robot parameters.

    Notes
    -----
    One control step is a single ``stepSimulation`` call: the client's time step is
    ``control_dt`` split by pybullet into ``substeps`` fixed physics steps of ``physics_dt``
    (``numSubSteps``), which avoids a Python round trip per physics step.
    """

    def __init__(self, arena: ArenaSpec, config: SimConfig | None = None) -> None:
        self.arena = arena
        self.config = config or SimConfig()
        mode = p.GUI if self.config.connection is ConnectionMode.GUI else p.DIRECT
        self.client: int = p.connect(mode)
        if self.client < 0:
            raise RuntimeError("could not connect to pybullet")
        self.rebuild()

    def rebuild(self) -> None:
        """Empty the client and build the arena and the robot afresh.

        A teleport alone (:meth:`place_robot`) keeps the solver's cached contacts and
        warm-start state, so two seeded resets to the same pose could step differently (seen in
        R1). A seeded reset therefore rebuilds the world; ``self.robot`` is a new
        :class:`EPuck` afterwards.
        """
        cid = self.client
        c = self.config
        p.resetSimulation(physicsClientId=cid)
        p.setGravity(0.0, 0.0, -9.81, physicsClientId=cid)
        p.setPhysicsEngineParameter(
            fixedTimeStep=c.control_dt,
            numSubSteps=c.substeps,
            numSolverIterations=c.solver_iterations,
            deterministicOverlappingPairs=1,
            physicsClientId=cid,
        )
        self.bodies: ArenaBodies = build_arena(self.arena, cid)
        self.robot = EPuck(cid, c.robot)
        self.sim_time = 0.0

    def place_robot(self, x: float, y: float, yaw: float) -> None:
        """Teleport the robot at rest to a pose (used only by resets/respawns)."""
        self.robot.reset_pose(x, y, yaw)

    def step(self, left: float, right: float) -> None:
        """Command the wheels and advance the physics by one control step.

        Parameters
        ----------
        left, right : float
            Wheel speeds (rad/s).
        """
        self.robot.apply_action(left, right)
        p.stepSimulation(physicsClientId=self.client)
        self.sim_time += self.config.control_dt

    def in_collision(self) -> bool:
        """True when the robot touches a wall or a block."""
        return self.robot.touching(self.bodies.obstacles)

    def render_top(self, width: int = 480, height: int = 480) -> np.ndarray:
        """Top view of the arena from far above with a narrow lens (nearly orthographic).

        Returns
        -------
        np.ndarray, shape (height, width, 3), uint8
            RGB image; image ``x`` is world ``+x``, image up is world ``+y``.
        """
        w, d = self.arena.size
        extent = max(w, d) + 0.1
        fov = 8.0
        dist = (extent / 2) / math.tan(math.radians(fov / 2))
        view = p.computeViewMatrix(
            cameraEyePosition=(0, 0, dist),
            cameraTargetPosition=(0, 0, 0),
            cameraUpVector=(0, 1, 0),
            physicsClientId=self.client,
        )
        proj = p.computeProjectionMatrixFOV(
            fov=fov,
            aspect=width / height,
            nearVal=dist - 0.5,
            farVal=dist + 0.5,
            physicsClientId=self.client,
        )
        _, _, rgba, _, _ = p.getCameraImage(
            width,
            height,
            viewMatrix=view,
            projectionMatrix=proj,
            renderer=p.ER_TINY_RENDERER,
            lightDirection=(0.3, 0.4, 1.0),
            physicsClientId=self.client,
        )
        return np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)[:, :, :3]

    def close(self) -> None:
        """Disconnect the pybullet client (idempotent)."""
        if self.client >= 0:
            try:
                p.disconnect(physicsClientId=self.client)
            except p.error:
                pass
            self.client = -1
