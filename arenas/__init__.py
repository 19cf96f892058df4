"""Arenas as data files: the paper's R1..R5 (``r1.json`` ... ``r5.json``) and user files.

See ``arenas/README.md`` for the JSON format.

The package imports no pybullet (a platform node loads arena specs, never a simulation):
:mod:`dfrl.arenas.builder` and the robots' simulation import it through
:mod:`dfrl.arenas.pybullet_quiet`, without its build-time banner.
"""

from dfrl.arenas.spec import (
    HELD_OUT_ARENAS,
    PAPER_ARENAS,
    WALL_THICKNESS,
    ArenaError,
    ArenaSpec,
    Block,
    StartSpec,
    builtin_arena_names,
    load_arena,
    parse_arena,
)

__all__ = [
    "HELD_OUT_ARENAS",
    "PAPER_ARENAS",
    "WALL_THICKNESS",
    "ArenaError",
    "ArenaSpec",
    "Block",
    "StartSpec",
    "build_arena",
    "builtin_arena_names",
    "load_arena",
    "parse_arena",
]


def build_arena(spec: ArenaSpec, client: int):  # noqa: ANN201 - re-export without importing pybullet eagerly
    """Create ``spec`` in pybullet client ``client``; see
    :func:`dfrl.arenas.builder.build_arena`."""
    from dfrl.arenas.builder import build_arena as _build

    return _build(spec, client)
