"""Footprint geometry of arena blocks: corners and overlap (used to validate arena files)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np


class Footprint(Protocol):
    """What the geometry needs of a block (:class:`dfrl.arenas.spec.Block` has it)."""

    @property
    def center(self) -> Sequence[float]: ...

    @property
    def size(self) -> Sequence[float]: ...

    @property
    def yaw(self) -> float: ...


def corners(block: Footprint) -> np.ndarray:
    """The footprint's four corners, shape (4, 2)."""
    c, s = math.cos(block.yaw), math.sin(block.yaw)
    hx, hy = block.size[0] / 2.0, block.size[1] / 2.0
    local = np.array([[hx, hy], [-hx, hy], [-hx, -hy], [hx, -hy]])
    rot = np.array([[c, -s], [s, c]])
    return local @ rot.T + np.asarray(block.center)


def blocks_overlap(a: Footprint, b: Footprint, tolerance: float = 1e-9) -> bool:
    """True when two footprints share area (touching edges do not count).

    Separating-axis test on the two rectangles' edge normals.
    """
    ca, cb = corners(a), corners(b)
    for yaw in (a.yaw, b.yaw):
        for axis in ((math.cos(yaw), math.sin(yaw)), (-math.sin(yaw), math.cos(yaw))):
            pa, pb = ca @ axis, cb @ axis
            if pa.max() <= pb.min() + tolerance or pb.max() <= pa.min() + tolerance:
                return False
    return True
