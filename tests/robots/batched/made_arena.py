"""An arena file the tests make up: a floor of a random size with random rotated blocks of
random heights (some too low for the IR rays), never seen by the simulators' authors."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from dfrl.arenas.spec import ArenaError, load_arena


def make_arena(path: Path, seed: int, blocks: int = 6) -> Path:
    """Write an arena with ``blocks`` non-overlapping random blocks to ``path``; returns it."""
    rng = np.random.default_rng(seed)
    w, d = float(rng.uniform(0.8, 1.4)), float(rng.uniform(0.8, 1.4))
    placed: list[dict] = []
    for _ in range(200):  # bounded: 200 candidate blocks
        if len(placed) == blocks:
            break
        sx, sy = rng.uniform(0.03, 0.25, size=2)
        block = {
            "center": [
                float(rng.uniform(-w / 2 + 0.15, w / 2 - 0.15)),
                float(rng.uniform(-d / 2 + 0.15, d / 2 - 0.15)),
            ],
            "size": [float(sx), float(sy), float(rng.choice([0.02, 0.05, 0.1]))],
            "yaw": float(rng.uniform(-math.pi, math.pi)),
        }
        spec = {
            "name": "made",
            "size": [w, d],
            "wall_height": 0.08,
            "blocks": placed + [block],
            "start": {"random": True},
        }
        path.write_text(json.dumps(spec), encoding="utf-8")
        try:
            load_arena(str(path))
        except ArenaError:
            continue  # overlapping: draw another
        placed.append(block)
    spec = {
        "name": f"made{seed}",
        "size": [w, d],
        "wall_height": 0.08,
        "blocks": placed,
        "start": {"random": True},
        "description": f"made up by tests/robots/batched/made_arena.py, seed {seed}",
    }
    path.write_text(json.dumps(spec, indent=1), encoding="utf-8")
    load_arena(str(path))
    return path
