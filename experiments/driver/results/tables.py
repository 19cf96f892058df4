"""The saved tables of a results folder: their sums (what the summary reports) and, for a run
that was interrupted, tables kept from the robots' last checkpoints.

A robot process writes ``tables/<robot>.npy`` at its end and again after a share that comes
later (the last share), so these files, not the last metrics row (taken before the last
share), hold the robots' final tables.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from dfrl.experiments.robot_host.checkpoint import load_checkpoint


def table_path(out_dir: str | Path, robot: str) -> Path:
    return Path(out_dir) / "tables" / f"{robot}.npy"


def table_sum(out_dir: str | Path, robot: str) -> float | None:
    """Sum of ``tables/<robot>.npy`` (None: no such table)."""
    p = table_path(out_dir, robot)
    if not p.is_file():
        return None
    return float(np.load(p, allow_pickle=False).sum())


def keep_checkpoints(out_dir: str | Path, robots: list[str]) -> list[str]:
    """For every robot without ``tables/<robot>.npy``, write it (and ``.visits.npy``) from
    ``checkpoint/<robot>.npy``, with a ``.json`` that says so (its iteration and shares).
    Returns the robots whose table came from a checkpoint."""
    out = Path(out_dir)
    kept = []
    for rid in robots:
        target = table_path(out, rid)
        if target.is_file() or not (out / "checkpoint" / f"{rid}.npy").is_file():
            continue
        try:
            cp = load_checkpoint(out / "checkpoint", rid)
        except (OSError, ValueError):
            continue
        target.parent.mkdir(parents=True, exist_ok=True)
        np.save(target, cp.q)
        np.save(target.with_suffix(".visits.npy"), cp.visits)
        doc = {"source": f"checkpoint/{rid}.npy (the run was interrupted)",
               "iteration": cp.iteration, "shares": cp.shares, "shape": list(cp.q.shape),
               "dtype": "float64"}
        target.with_suffix(".json").write_text(json.dumps(doc, indent=2) + "\n",
                                               encoding="utf-8")
        kept.append(rid)
    return kept
