"""An e-puck-style differential-drive robot in pybullet.

The robot is a rigid multibody: a cylindrical body (7.4 cm across) carrying two free-spinning
caster spheres (frictionless, so the body rests level) and two wheels on revolute joints driven
by pybullet's velocity motors. Eight infrared proximity sensors are horizontal rays cast from the
body's rim at the angles of the real e-puck's ``ps0`` ... ``ps7``, in one ``rayTestBatch`` call
expressed in the body frame.

Frames: the base frame has ``x`` forward, ``y`` to the left, ``z`` up, origin on the wheel axle.
Every pybullet call passes ``physicsClientId``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dfrl.arenas.pybullet_quiet import load as _load_pybullet

p = _load_pybullet()  # pybullet, without its build-time banner

#: Sensor directions of the e-puck's ``ps0`` ... ``ps7`` (rad, counter-clockwise from forward):
#: ps0/ps7 front right/left, ps1/ps6 diagonals, ps2/ps5 sides, ps3/ps4 rear.
EPUCK_SENSOR_ANGLES: tuple[float, ...] = (-0.30, -0.80, -1.57, -2.64, 2.64, 1.57, 0.80, 0.30)

#: Names of the sensors, index-aligned with :data:`EPUCK_SENSOR_ANGLES`.
SENSOR_NAMES: tuple[str, ...] = tuple(f"ps{i}" for i in range(8))


@dataclass(frozen=True)
class EPuckConfig:
    """Geometry, dynamics and sensing of the robot (SI units).

    Defaults follow the e-puck: 74 mm diameter, 41 mm wheels 53 mm apart, wheel speed up to
    6.28 rad/s (about 13 cm/s), IR sensors that see a few centimetres.

    Attributes
    ----------
    body_radius, body_height, body_mass : float
        Body cylinder (m, m, kg).
    wheel_radius, wheel_width, wheel_mass, axle_length : float
        Wheels (m, m, kg) and the distance between their mid-planes (m).
    max_wheel_speed : float
        Largest commanded wheel speed (rad/s); commands are clipped to it.
    max_wheel_torque : float
        Torque limit of each velocity motor (N m).
    wheel_friction : float
        Lateral friction coefficient of the tyres.
    sensor_range : float
        How far beyond the body rim an IR sensor sees (m).
    sensor_height : float
        Height of the IR rays above the floor (m).
    sensor_angles : tuple[float, ...]
        Direction of each sensor in the body frame (rad).
    sensor_noise_std : float
        Standard deviation of Gaussian noise added to the distance of a sensor that sees
        something (m); 0 disables noise. Readings stay in ``[0, sensor_range]``.
    """

    body_radius: float = 0.037
    body_height: float = 0.045
    body_mass: float = 0.15
    wheel_radius: float = 0.0205
    wheel_width: float = 0.004
    wheel_mass: float = 0.01
    axle_length: float = 0.053
    max_wheel_speed: float = 6.28
    max_wheel_torque: float = 0.05
    wheel_friction: float = 1.0
    sensor_range: float = 0.06
    sensor_height: float = 0.03
    sensor_angles: tuple[float, ...] = EPUCK_SENSOR_ANGLES
    sensor_noise_std: float = 0.0

    def __post_init__(self) -> None:
        for name in (
            "body_radius",
            "body_height",
            "body_mass",
            "wheel_radius",
            "wheel_width",
            "wheel_mass",
            "axle_length",
            "max_wheel_speed",
            "max_wheel_torque",
            "sensor_range",
            "sensor_height",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"EPuckConfig.{name} must be a positive number, got {value}")
        if self.sensor_noise_std < 0:
            raise ValueError("EPuckConfig.sensor_noise_std must be >= 0")
        if not self.sensor_angles:
            raise ValueError("EPuckConfig.sensor_angles must not be empty")
        if self.axle_length / 2 + self.wheel_width / 2 >= self.body_radius:
            raise ValueError("the wheels must fit inside the body radius")

    @property
    def max_linear_speed(self) -> float:
        """Forward speed with both wheels at :attr:`max_wheel_speed` (m/s)."""
        return self.max_wheel_speed * self.wheel_radius


def yaw_to_quaternion(yaw: float) -> tuple[float, float, float, float]:
    """Quaternion ``(x, y, z, w)`` of a rotation by ``yaw`` about the vertical axis."""
    return (0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0))


class EPuck:
    """The robot body in one pybullet client.

    Parameters
    ----------
    client : int
        pybullet physics client id.
    config : EPuckConfig
        Robot parameters.
    pose : tuple[float, float, float]
        Initial ``(x, y, yaw)``.

    Notes
    -----
    Joint 0 is the left wheel (``+y``), joint 1 the right wheel; a positive wheel speed
    drives the robot forward.
    """

    LEFT: int = 0
    RIGHT: int = 1

    def __init__(
        self,
        client: int,
        config: EPuckConfig | None = None,
        pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> None:
        self.client = client
        self.config = config or EPuckConfig()
        self.body_id = self._create_body(pose)
        c = self.config
        # Rays start inside the body, beyond the wheels (a ray that starts inside a convex
        # shape ignores it), so that a sensor still sees a wall the body presses into.
        start = c.axle_length / 2 + c.wheel_width / 2 + 1e-3
        self._inset = c.body_radius - start
        self._ray_len = c.sensor_range + self._inset
        z = c.sensor_height - c.wheel_radius
        cos = np.cos(np.asarray(c.sensor_angles))
        sin = np.sin(np.asarray(c.sensor_angles))
        end = start + self._ray_len
        #: ray starts and ends in the body frame, shape (n_sensors, 3)
        self._ray_from = [(start * a, start * b, z) for a, b in zip(cos, sin)]
        self._ray_to = [(end * a, end * b, z) for a, b in zip(cos, sin)]
        self._wheels = [self.LEFT, self.RIGHT]
        self._forces = [c.max_wheel_torque, c.max_wheel_torque]

    @property
    def n_sensors(self) -> int:
        """Number of proximity sensors."""
        return len(self.config.sensor_angles)

    def _create_body(self, pose: tuple[float, float, float]) -> int:
        c = self.config
        cid = self.client
        r_wheel = c.wheel_radius
        caster_r = 0.005
        body_bottom = 0.006  # ground clearance of the body (m)
        body_z = body_bottom + c.body_height / 2 - r_wheel  # body centre in the axle frame
        caster_z = -r_wheel + caster_r + 0.001  # 1 mm gap: the wheels carry the weight
        caster_x = c.body_radius - 0.012
        base_col = p.createCollisionShapeArray(
            shapeTypes=[p.GEOM_CYLINDER, p.GEOM_SPHERE, p.GEOM_SPHERE],
            radii=[c.body_radius, caster_r, caster_r],
            lengths=[c.body_height, 0.0, 0.0],
            collisionFramePositions=[
                (0, 0, body_z),
                (caster_x, 0, caster_z),
                (-caster_x, 0, caster_z),
            ],
            physicsClientId=cid,
        )
        base_vis = p.createVisualShape(
            p.GEOM_CYLINDER,
            radius=c.body_radius,
            length=c.body_height,
            visualFramePosition=(0, 0, body_z),
            rgbaColor=(0.25, 0.55, 0.30, 1.0),
            physicsClientId=cid,
        )
        wheel_orn = p.getQuaternionFromEuler((math.pi / 2, 0.0, 0.0))
        wheel_col = p.createCollisionShape(
            p.GEOM_CYLINDER,
            radius=r_wheel,
            height=c.wheel_width,
            collisionFrameOrientation=wheel_orn,
            physicsClientId=cid,
        )
        wheel_vis = p.createVisualShape(
            p.GEOM_CYLINDER,
            radius=r_wheel,
            length=c.wheel_width,
            visualFrameOrientation=wheel_orn,
            rgbaColor=(0.1, 0.1, 0.1, 1.0),
            physicsClientId=cid,
        )
        half_axle = c.axle_length / 2
        body = p.createMultiBody(
            baseMass=c.body_mass,
            baseCollisionShapeIndex=base_col,
            baseVisualShapeIndex=base_vis,
            basePosition=(pose[0], pose[1], r_wheel),
            baseOrientation=yaw_to_quaternion(pose[2]),
            linkMasses=[c.wheel_mass, c.wheel_mass],
            linkCollisionShapeIndices=[wheel_col, wheel_col],
            linkVisualShapeIndices=[wheel_vis, wheel_vis],
            linkPositions=[(0, half_axle, 0), (0, -half_axle, 0)],
            linkOrientations=[(0, 0, 0, 1), (0, 0, 0, 1)],
            linkInertialFramePositions=[(0, 0, 0), (0, 0, 0)],
            linkInertialFrameOrientations=[(0, 0, 0, 1), (0, 0, 0, 1)],
            linkParentIndices=[0, 0],
            linkJointTypes=[p.JOINT_REVOLUTE, p.JOINT_REVOLUTE],
            linkJointAxis=[(0, 1, 0), (0, 1, 0)],
            physicsClientId=cid,
        )
        # Frictionless body and casters (they slide), grippy tyres.
        p.changeDynamics(
            body,
            -1,
            lateralFriction=0.0,
            rollingFriction=0.0,
            spinningFriction=0.0,
            physicsClientId=cid,
        )
        for link in (self.LEFT, self.RIGHT):
            p.changeDynamics(
                body,
                link,
                lateralFriction=c.wheel_friction,
                rollingFriction=0.0,
                spinningFriction=0.0,
                jointDamping=0.0,
                physicsClientId=cid,
            )
        return body

    def reset_pose(self, x: float, y: float, yaw: float) -> None:
        """Place the robot at rest at ``(x, y, yaw)`` with still wheels."""
        cid = self.client
        p.resetBasePositionAndOrientation(
            self.body_id,
            (x, y, self.config.wheel_radius),
            yaw_to_quaternion(yaw),
            physicsClientId=cid,
        )
        p.resetBaseVelocity(self.body_id, (0, 0, 0), (0, 0, 0), physicsClientId=cid)
        for joint in self._wheels:
            p.resetJointState(self.body_id, joint, 0.0, 0.0, physicsClientId=cid)
        self.apply_action(0.0, 0.0)

    def apply_action(self, left: float, right: float) -> None:
        """Set the wheel speed targets of the velocity motors.

        Parameters
        ----------
        left, right : float
            Wheel angular velocities (rad/s), clipped to ``+-max_wheel_speed``.
        """
        vmax = self.config.max_wheel_speed
        p.setJointMotorControlArray(
            self.body_id,
            self._wheels,
            p.VELOCITY_CONTROL,
            targetVelocities=[min(max(left, -vmax), vmax), min(max(right, -vmax), vmax)],
            forces=self._forces,
            physicsClientId=self.client,
        )

    def sense(self, rng: np.random.Generator | None = None) -> np.ndarray:
        """Read the IR sensors.

        Parameters
        ----------
        rng : np.random.Generator, optional
            Noise source; required when ``sensor_noise_std > 0``.

        Returns
        -------
        np.ndarray, shape (n_sensors,), float64
            Distance from the body rim to the first obstacle along each ray (m),
            ``sensor_range`` when nothing is in range.
        """
        hits = p.rayTestBatch(
            self._ray_from,
            self._ray_to,
            parentObjectUniqueId=self.body_id,
            parentLinkIndex=-1,
            numThreads=1,
            physicsClientId=self.client,
        )
        rng_ = self.config.sensor_range
        frac = np.fromiter((h[2] for h in hits), dtype=np.float64, count=len(hits))
        dist = np.clip(frac * self._ray_len - self._inset, 0.0, rng_)
        std = self.config.sensor_noise_std
        if std > 0.0:
            if rng is None:
                raise ValueError("sensor noise is on: pass the environment's rng to sense()")
            seen = dist < rng_
            noise = rng.normal(0.0, std, size=dist.shape)
            dist = np.where(seen, np.clip(dist + noise, 0.0, rng_), dist)
        return dist

    def sensor_rays(self, distances: np.ndarray) -> np.ndarray:
        """The sensors' rays in the world frame, from the body's rim to what each one sees.

        Parameters
        ----------
        distances : np.ndarray, shape (n_sensors,)
            As returned by :meth:`sense`.

        Returns
        -------
        np.ndarray, shape (n_sensors, 2, 2)
            ``[i, 0]`` is the rim point ``(x, y)`` of sensor ``i``, ``[i, 1]`` the end of its
            ray (an obstacle, or ``sensor_range`` away).
        """
        x, y, yaw = self.pose()
        angles = yaw + np.asarray(self.config.sensor_angles)
        rim = self.config.body_radius
        far = rim + np.asarray(distances, dtype=np.float64)
        unit = np.stack([np.cos(angles), np.sin(angles)], axis=1)
        centre = np.array([x, y])
        return np.stack([centre + rim * unit, centre + far[:, None] * unit], axis=1)

    def proximity(self, distances: np.ndarray) -> np.ndarray:
        """Map distances to proximities ``1 - d / sensor_range`` in ``[0, 1]`` (1 = touching)."""
        return 1.0 - distances / self.config.sensor_range

    def pose(self) -> tuple[float, float, float]:
        """Current ``(x, y, yaw)`` of the base."""
        pos, orn = p.getBasePositionAndOrientation(self.body_id, physicsClientId=self.client)
        x, y, z, w = orn
        yaw = math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))
        return (pos[0], pos[1], yaw)

    def touching(self, bodies: tuple[int, ...]) -> bool:
        """True when the robot is in contact with any of ``bodies``."""
        for body in bodies:
            if p.getContactPoints(bodyA=self.body_id, bodyB=body, physicsClientId=self.client):
                return True
        return False
