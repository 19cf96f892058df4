"""Loading an :class:`~dfrl.arenas.spec.ArenaSpec` into a pybullet client."""

from __future__ import annotations

import math
from dataclasses import dataclass

from dfrl.arenas.pybullet_quiet import load as _load_pybullet
from dfrl.arenas.spec import WALL_THICKNESS, ArenaSpec

p = _load_pybullet()  # pybullet, without its build-time banner

#: RGBA colours used for rendering.
FLOOR_RGBA: tuple[float, float, float, float] = (0.93, 0.93, 0.90, 1.0)
WALL_RGBA: tuple[float, float, float, float] = (0.45, 0.45, 0.50, 1.0)
BLOCK_RGBA: tuple[float, float, float, float] = (0.80, 0.33, 0.25, 1.0)


@dataclass(frozen=True)
class ArenaBodies:
    """pybullet body ids of a loaded arena.

    Attributes
    ----------
    floor : int
        The ground: a static plane at ``z = 0`` (drawn as a thin box around the arena).
    walls : int
        One static body holding the four boundary walls.
    blocks : int or None
        One static body holding every block, or None for an arena without blocks.
    """

    floor: int
    walls: int
    blocks: int | None

    @property
    def obstacles(self) -> tuple[int, ...]:
        """Bodies whose contact with the robot counts as a collision."""
        return (self.walls,) if self.blocks is None else (self.walls, self.blocks)


def _yaw_quat(yaw: float) -> tuple[float, float, float, float]:
    return (0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0))


def _static_boxes(
    client: int,
    half_extents: list[tuple[float, float, float]],
    positions: list[tuple[float, float, float]],
    yaws: list[float],
    rgba: tuple[float, float, float, float],
) -> int:
    """One static (mass 0) body made of several boxes."""
    n = len(half_extents)
    orientations = [_yaw_quat(y) for y in yaws]
    col = p.createCollisionShapeArray(
        shapeTypes=[p.GEOM_BOX] * n,
        halfExtents=half_extents,
        collisionFramePositions=positions,
        collisionFrameOrientations=orientations,
        physicsClientId=client,
    )
    vis = p.createVisualShapeArray(
        shapeTypes=[p.GEOM_BOX] * n,
        halfExtents=half_extents,
        visualFramePositions=positions,
        visualFrameOrientations=orientations,
        physicsClientId=client,
    )
    body = p.createMultiBody(
        baseMass=0.0,
        baseCollisionShapeIndex=col,
        baseVisualShapeIndex=vis,
        physicsClientId=client,
    )
    p.changeVisualShape(body, -1, rgbaColor=rgba, physicsClientId=client)
    return body


def build_arena(spec: ArenaSpec, client: int) -> ArenaBodies:
    """Create the floor, walls and blocks of ``spec`` in pybullet client ``client``.

    Parameters
    ----------
    spec : ArenaSpec
        The arena.
    client : int
        pybullet physics client id.

    Returns
    -------
    ArenaBodies
        The created bodies; all are static.
    """
    w, d = spec.size
    t = WALL_THICKNESS
    # The floor the camera sees ends at the walls' inner faces; an infinite plane collides
    # faster than a box, so the collision shape stays a plane.
    floor_half = (w / 2, d / 2, 0.01)
    floor_col = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=client)
    floor_vis = p.createVisualShape(
        p.GEOM_BOX,
        halfExtents=floor_half,
        visualFramePosition=(0.0, 0.0, -floor_half[2]),
        rgbaColor=FLOOR_RGBA,
        physicsClientId=client,
    )
    floor = p.createMultiBody(
        baseMass=0.0,
        baseCollisionShapeIndex=floor_col,
        baseVisualShapeIndex=floor_vis,
        physicsClientId=client,
    )
    h = spec.wall_height
    walls = _static_boxes(
        client,
        half_extents=[
            (w / 2 + t, t / 2, h / 2),
            (w / 2 + t, t / 2, h / 2),
            (t / 2, d / 2 + t, h / 2),
            (t / 2, d / 2 + t, h / 2),
        ],
        positions=[
            (0.0, d / 2 + t / 2, h / 2),
            (0.0, -d / 2 - t / 2, h / 2),
            (w / 2 + t / 2, 0.0, h / 2),
            (-w / 2 - t / 2, 0.0, h / 2),
        ],
        yaws=[0.0] * 4,
        rgba=WALL_RGBA,
    )
    blocks = None
    if spec.blocks:
        blocks = _static_boxes(
            client,
            half_extents=[(b.size[0] / 2, b.size[1] / 2, b.size[2] / 2) for b in spec.blocks],
            positions=[(b.center[0], b.center[1], b.size[2] / 2) for b in spec.blocks],
            yaws=[b.yaw for b in spec.blocks],
            rgba=BLOCK_RGBA,
        )
    return ArenaBodies(floor=floor, walls=walls, blocks=blocks)
