"""Arenas as arrays for the batched simulator: every wall and block is a rotated box.

One row per box, columns :data:`BOX_COLUMNS`: centre, half extents, the cosine and sine of its
yaw, and whether the IR rays (at ``sensor_height`` above the floor) see it. The boundary walls
are the four boxes of :func:`dfrl.arenas.builder.build_arena` (``WALL_THICKNESS`` thick, just
outside the floor), so inside the floor the signed distance to them is the distance to the
floor's edge, as in :meth:`dfrl.arenas.spec.ArenaSpec.clearance`.

Several arenas are packed into one table (:class:`PackedArenas`); robot ``i`` uses the rows
``first[a] .. first[a] + count[a]`` of its arena ``a``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dfrl.arenas.spec import WALL_THICKNESS, ArenaSpec

#: Columns of a box row.
BOX_COLUMNS: tuple[str, ...] = ("cx", "cy", "hx", "hy", "cos", "sin", "seen")


def arena_boxes(arena: ArenaSpec, sensor_height: float) -> np.ndarray:
    """The walls and blocks of ``arena`` as box rows, shape (4 + n_blocks, 7).

    Parameters
    ----------
    arena : ArenaSpec
    sensor_height : float
        Height of the IR rays (m): a box lower than this is not seen (it still collides).
    """
    hw, hd = arena.size[0] / 2.0, arena.size[1] / 2.0
    t = WALL_THICKNESS
    seen = 1.0 if arena.wall_height > sensor_height else 0.0
    rows = [
        (hw + t / 2, 0.0, t / 2, hd + t, 1.0, 0.0, seen),
        (-hw - t / 2, 0.0, t / 2, hd + t, 1.0, 0.0, seen),
        (0.0, hd + t / 2, hw + t, t / 2, 1.0, 0.0, seen),
        (0.0, -hd - t / 2, hw + t, t / 2, 1.0, 0.0, seen),
    ]
    for b in arena.blocks:
        rows.append(
            (
                b.center[0],
                b.center[1],
                b.size[0] / 2.0,
                b.size[1] / 2.0,
                math.cos(b.yaw),
                math.sin(b.yaw),
                1.0 if b.size[2] > sensor_height else 0.0,
            )
        )
    return np.asarray(rows, dtype=np.float64)


@dataclass(frozen=True)
class PackedArenas:
    """Several arenas in one box table.

    Attributes
    ----------
    arenas : tuple[ArenaSpec, ...]
    boxes : np.ndarray, shape (n_boxes, 7)
    first, count : np.ndarray, shape (n_arenas,), int64
        Rows of each arena.
    half : np.ndarray, shape (n_arenas, 2)
        Half width and half depth of each floor.
    start : np.ndarray, shape (n_arenas, 4)
        ``(random, x, y, yaw)`` of each arena's start rule (``random`` 1.0 or 0.0).
    """

    arenas: tuple[ArenaSpec, ...]
    boxes: np.ndarray
    first: np.ndarray
    count: np.ndarray
    half: np.ndarray
    start: np.ndarray


def pack_arenas(arenas: Sequence[ArenaSpec], sensor_height: float) -> PackedArenas:
    """Pack ``arenas`` (each once) into one :class:`PackedArenas`."""
    tables = [arena_boxes(a, sensor_height) for a in arenas]
    count = np.array([len(t) for t in tables], dtype=np.int64)
    first = np.concatenate([[0], np.cumsum(count)[:-1]]).astype(np.int64)
    half = np.array([[a.size[0] / 2.0, a.size[1] / 2.0] for a in arenas], dtype=np.float64)
    start = np.array(
        [(1.0, 0.0, 0.0, 0.0) if a.start.random else (0.0, *(a.start.pose or ())) for a in arenas],
        dtype=np.float64,
    )
    return PackedArenas(
        arenas=tuple(arenas),
        boxes=np.concatenate(tables),
        first=first,
        count=count,
        half=half,
        start=start,
    )
