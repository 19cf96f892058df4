"""Arena files: the public JSON format, its validation and free-space geometry.

An arena is a rectangular floor bounded by walls, with solid rectangular blocks on it.
The format is documented in ``arenas/README.md``; this module is its reference parser.
Coordinates are metres in a frame whose origin is the centre of the floor, ``x`` to the
right, ``y`` up (top view), ``z`` vertical; yaw angles are radians, counter-clockwise.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dfrl.arenas.geometry import blocks_overlap

#: Thickness of the boundary walls (m). The walls stand just outside the floor rectangle,
#: so the free floor is exactly ``size[0]`` by ``size[1]``.
WALL_THICKNESS: float = 0.02

#: Folder of the built-in arena files (package data).
_ARENA_DIR = Path(__file__).resolve().parent

#: Clearance a fixed start pose needs from every block and wall (m): the e-puck's body
#: radius (``dfrl.robots.epuck.EPuckConfig.body_radius``), so that a robot placed there
#: touches nothing. The arena layer knows no robot; this is the robot it is made for.
START_CLEARANCE: float = 0.037

_TOP_LEVEL_KEYS = {"name", "size", "wall_height", "blocks", "start", "description", "allow_overlap"}
_BLOCK_KEYS = {"center", "size", "yaw"}


class ArenaError(ValueError):
    """A bad arena file or name. The message says which file, where, and what is wrong."""


@dataclass(frozen=True)
class Block:
    """A solid box standing on the floor.

    Attributes
    ----------
    center : tuple[float, float]
        ``(x, y)`` of the box centre on the floor (m).
    size : tuple[float, float, float]
        Full extents ``(sx, sy, sz)`` (m); ``sz`` is the height.
    yaw : float
        Rotation about the vertical axis (rad).
    """

    center: tuple[float, float]
    size: tuple[float, float, float]
    yaw: float = 0.0

    def clearance(self, xy: np.ndarray) -> np.ndarray:
        """Distance from points to the block's footprint (0 inside).

        Parameters
        ----------
        xy : np.ndarray, shape (n, 2)
            Points on the floor.

        Returns
        -------
        np.ndarray, shape (n,)
            Euclidean distance to the rotated rectangle.
        """
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        d = np.asarray(xy, dtype=float) - np.asarray(self.center)
        local = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], axis=1)
        half = np.asarray(self.size[:2]) / 2.0
        outside = np.maximum(np.abs(local) - half, 0.0)
        return np.hypot(outside[:, 0], outside[:, 1])


@dataclass(frozen=True)
class StartSpec:
    """Where the robot starts after a seeded reset.

    Attributes
    ----------
    pose : tuple[float, float, float] or None
        ``(x, y, yaw)``; None means a random free pose.
    """

    pose: tuple[float, float, float] | None = None

    @property
    def random(self) -> bool:
        """True when the start pose is drawn at random."""
        return self.pose is None


@dataclass(frozen=True)
class ArenaSpec:
    """A validated arena.

    Attributes
    ----------
    name : str
        Short name (``"r4"``).
    size : tuple[float, float]
        Floor ``(width, depth)`` (m), i.e. extents along x and y.
    wall_height : float
        Height of the boundary walls (m).
    blocks : tuple[Block, ...]
        Obstacles on the floor.
    start : StartSpec
        Start pose rule.
    description : str
        Free text.
    source : str
        Where the spec was read from (a path or ``"<dict>"``).
    allow_overlap : bool
        Blocks may overlap (otherwise overlapping blocks are an error).
    """

    name: str
    size: tuple[float, float]
    wall_height: float
    blocks: tuple[Block, ...] = ()
    start: StartSpec = field(default_factory=StartSpec)
    description: str = ""
    source: str = "<dict>"
    allow_overlap: bool = False

    def clearance(self, xy: np.ndarray) -> np.ndarray:
        """Distance from floor points to the nearest wall or block.

        Parameters
        ----------
        xy : np.ndarray, shape (n, 2)

        Returns
        -------
        np.ndarray, shape (n,)
            Clearance in metres; 0 (or negative outside the floor) when not free.
        """
        xy = np.atleast_2d(np.asarray(xy, dtype=float))
        hw, hd = self.size[0] / 2.0, self.size[1] / 2.0
        dist = np.minimum.reduce([hw - xy[:, 0], xy[:, 0] + hw, hd - xy[:, 1], xy[:, 1] + hd])
        for block in self.blocks:
            dist = np.minimum(dist, block.clearance(xy))
        return dist

    def is_free(self, x: float, y: float, clearance: float) -> bool:
        """True when a disc of radius ``clearance`` at ``(x, y)`` touches nothing."""
        return bool(self.clearance(np.array([[x, y]]))[0] >= clearance)

    def sample_free_pose(
        self, rng: np.random.Generator, clearance: float, max_tries: int = 10_000
    ) -> tuple[float, float, float]:
        """Draw a uniformly random pose whose disc of radius ``clearance`` is free.

        Parameters
        ----------
        rng : np.random.Generator
            Source of all randomness (the environment's ``np_random``).
        clearance : float
            Required free radius around the pose (m).
        max_tries : int
            Rejection-sampling budget.

        Returns
        -------
        tuple[float, float, float]
            ``(x, y, yaw)``.

        Raises
        ------
        ArenaError
            If no free pose was found (the arena is too crowded for the robot).
        """
        hw, hd = self.size[0] / 2.0, self.size[1] / 2.0
        for _ in range(max_tries):
            x = float(rng.uniform(-hw + clearance, hw - clearance))
            y = float(rng.uniform(-hd + clearance, hd - clearance))
            yaw = float(rng.uniform(-math.pi, math.pi))
            if self.is_free(x, y, clearance):
                return (x, y, yaw)
        raise ArenaError(
            f"{self.source}: no free pose with clearance {clearance} m found in "
            f"{max_tries} tries; the arena is too crowded"
        )

    def to_dict(self) -> dict[str, Any]:
        """The arena in the JSON file format."""
        out: dict[str, Any] = {
            "name": self.name,
            "size": list(self.size),
            "wall_height": self.wall_height,
            "blocks": [
                {"center": list(b.center), "size": list(b.size), "yaw": b.yaw} for b in self.blocks
            ],
            "start": (
                {"random": True} if self.start.random else {"pose": list(self.start.pose or ())}
            ),
        }
        if self.description:
            out["description"] = self.description
        if self.allow_overlap:
            out["allow_overlap"] = True
        return out


def _fail(source: str, where: str, what: str) -> ArenaError:
    return ArenaError(f"{source}: {where}: {what}")


def _number(value: Any, source: str, where: str, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise _fail(source, where, f"expected a number, got {json.dumps(value)}")
    if not math.isfinite(value):
        raise _fail(source, where, f"expected a finite number, got {value}")
    if positive and value <= 0:
        raise _fail(source, where, f"expected a positive number, got {value}")
    return float(value)


def _vector(
    value: Any, n: int, source: str, where: str, positive: bool = False
) -> tuple[float, ...]:
    if not isinstance(value, list) or len(value) != n:
        raise _fail(source, where, f"expected a list of {n} numbers, got {json.dumps(value)}")
    return tuple(_number(v, source, f"{where}[{i}]", positive) for i, v in enumerate(value))


def parse_arena(data: Any, source: str = "<dict>") -> ArenaSpec:
    """Validate a decoded arena JSON object.

    Parameters
    ----------
    data : Any
        The decoded JSON value.
    source : str
        Name used in error messages (usually the file path).

    Returns
    -------
    ArenaSpec

    Raises
    ------
    ArenaError
        Naming the file, the offending key path (e.g. ``blocks[2].size[1]``) and the problem.
    """
    if not isinstance(data, dict):
        raise _fail(source, "top level", f"expected a JSON object, got {type(data).__name__}")
    unknown = sorted(set(data) - _TOP_LEVEL_KEYS)
    if unknown:
        raise _fail(
            source, "top level", f"unknown key(s) {unknown}; allowed: {sorted(_TOP_LEVEL_KEYS)}"
        )
    for key in ("name", "size", "wall_height", "blocks", "start"):
        if key not in data:
            raise _fail(source, "top level", f"missing required key '{key}'")
    name = data["name"]
    if not isinstance(name, str) or not name.strip():
        raise _fail(source, "name", f"expected a non-empty string, got {json.dumps(name)}")
    size = _vector(data["size"], 2, source, "size", positive=True)
    wall_height = _number(data["wall_height"], source, "wall_height", positive=True)
    description = data.get("description", "")
    if not isinstance(description, str):
        raise _fail(source, "description", "expected a string")

    raw_blocks = data["blocks"]
    if not isinstance(raw_blocks, list):
        raise _fail(source, "blocks", f"expected a list, got {json.dumps(raw_blocks)}")
    blocks = []
    hw, hd = size[0] / 2.0, size[1] / 2.0
    for i, raw in enumerate(raw_blocks):
        where = f"blocks[{i}]"
        if not isinstance(raw, dict):
            raise _fail(source, where, f"expected an object, got {json.dumps(raw)}")
        unknown = sorted(set(raw) - _BLOCK_KEYS)
        if unknown:
            raise _fail(source, where, f"unknown key(s) {unknown}; allowed: {sorted(_BLOCK_KEYS)}")
        for key in ("center", "size"):
            if key not in raw:
                raise _fail(source, where, f"missing required key '{key}'")
        center = _vector(raw["center"], 2, source, f"{where}.center")
        bsize = _vector(raw["size"], 3, source, f"{where}.size", positive=True)
        yaw = _number(raw.get("yaw", 0.0), source, f"{where}.yaw")
        if not (-hw < center[0] < hw and -hd < center[1] < hd):
            raise _fail(
                source,
                f"{where}.center",
                f"{list(center)} lies outside the floor x in ({-hw}, {hw}), y in ({-hd}, {hd})",
            )
        blocks.append(
            Block(center=(center[0], center[1]), size=(bsize[0], bsize[1], bsize[2]), yaw=yaw)
        )

    allow_overlap = data.get("allow_overlap", False)
    if not isinstance(allow_overlap, bool):
        raise _fail(
            source, "allow_overlap", f"expected true or false, got {json.dumps(allow_overlap)}"
        )
    if not allow_overlap:
        for i in range(len(blocks)):
            for j in range(i + 1, len(blocks)):
                if blocks_overlap(blocks[i], blocks[j]):
                    raise _fail(
                        source,
                        f"blocks[{j}]",
                        f'overlaps blocks[{i}] (set "allow_overlap": true if meant)',
                    )

    raw_start = data["start"]
    if not isinstance(raw_start, dict):
        raise _fail(source, "start", f"expected an object, got {json.dumps(raw_start)}")
    if set(raw_start) == {"random"}:
        if raw_start["random"] is not True:
            raise _fail(source, "start.random", "must be true (give 'pose' for a fixed start)")
        start = StartSpec(None)
    elif set(raw_start) == {"pose"}:
        pose = _vector(raw_start["pose"], 3, source, "start.pose")
        start = StartSpec((pose[0], pose[1], pose[2]))
    else:
        raise _fail(
            source,
            "start",
            f'expected exactly one of {{"pose": [x, y, yaw]}} or {{"random": true}}, '
            f"got keys {sorted(raw_start)}",
        )
    spec = ArenaSpec(
        name=name.strip(),
        size=(size[0], size[1]),
        wall_height=wall_height,
        blocks=tuple(blocks),
        start=start,
        description=description,
        source=source,
        allow_overlap=allow_overlap,
    )
    if start.pose is not None:
        x, y, _ = start.pose
        gap = float(spec.clearance(np.array([[x, y]]))[0])
        if gap < START_CLEARANCE:
            where = (
                "inside a block or outside the floor"
                if gap <= 0.0
                else (f"only {gap:.3f} m from a block or wall")
            )
            raise _fail(
                source,
                "start.pose",
                f"({x}, {y}) is {where}; a start pose needs {START_CLEARANCE} m "
                "(the robot's radius) of free floor around it",
            )
    return spec


#: The paper's five arenas, in order.
PAPER_ARENAS: tuple[str, ...] = ("r1", "r2", "r3", "r4", "r5")
#: Arenas no federation of the paper trains in, for transfer and generalisation tests:
#: ``h1`` a cluttered floor of thin pillars, ``h2`` a long loop corridor with slanted baffles.
HELD_OUT_ARENAS: tuple[str, ...] = ("h1", "h2")


def builtin_arena_names() -> list[str]:
    """Names of the arenas shipped with the package: :data:`PAPER_ARENAS` and
    :data:`HELD_OUT_ARENAS`, sorted."""
    return sorted(p.stem for p in _ARENA_DIR.glob("*.json"))


def load_arena(name_or_path: str | Path) -> ArenaSpec:
    """Load an arena by built-in name (``"r4"``, case-insensitive) or by file path.

    Parameters
    ----------
    name_or_path : str or Path
        A built-in name or the path of a JSON arena file.

    Returns
    -------
    ArenaSpec

    Raises
    ------
    ArenaError
        Unknown name, unreadable file, invalid JSON (with line and column) or invalid content.
    """
    text_name = str(name_or_path)
    path = Path(text_name)
    if not path.suffix and not path.exists():
        lowered = text_name.lower()
        if lowered not in builtin_arena_names():
            raise ArenaError(
                f"unknown arena '{text_name}': not a built-in arena "
                f"({', '.join(builtin_arena_names())}) nor an existing file"
            )
        resource = _ARENA_DIR / f"{lowered}.json"
        return _parse_text(resource.read_text(encoding="utf-8"), f"arenas/{lowered}.json")
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ArenaError(f"{path}: cannot read arena file: {exc.strerror or exc}") from exc
    return _parse_text(text, str(path))


def _parse_text(text: str, source: str) -> ArenaSpec:
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ArenaError(
            f"{source}: line {exc.lineno}, column {exc.colno}: invalid JSON: {exc.msg}"
        ) from exc
    return parse_arena(data, source)
