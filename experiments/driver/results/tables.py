"""The saved tables of a results folder: their sums (what the summary reports), the check that
each is whole, and tables kept from the robots' last checkpoints. A function learner (``linear``,
``dqn``) saves its parameter vector as ``params/<robot>.npy`` (+ ``.json``, format
``dfrl-params/2``) instead of a table: everything here treats it as its table (the sum is the
sum of the parameters).

A robot process writes ``tables/<robot>.npy`` at its end and again after a share that comes
later (the last share), so these files, not the robot's last ``metrics_<robot>.csv`` row
(taken before the last share), hold the robots' final tables (``metrics.csv``'s last row of a
robot has the sum after its last share). A robot killed while it wrote them (or an older robot
host that does not write them atomically) may leave a torn file: :func:`set_aside_unreadable`
moves it to ``tables/<robot>.npy.torn`` and says why, and :func:`keep_checkpoints` then
writes the table from the robot's last complete checkpoint, as for a robot that wrote none.
"""
from __future__ import annotations

import io
import json
import os
from pathlib import Path

import numpy as np

from dfrl.experiments.robot_host.checkpoint import atomic_write, load_checkpoint

__all__ = ["table_path", "params_path", "learnt_path", "table_sum", "set_aside_unreadable",
           "keep_checkpoints", "table_problems", "final_tables"]

#: What np.load and json raise on a torn or foreign file.
_UNREADABLE = (OSError, ValueError, EOFError)


def table_path(out_dir: str | Path, robot: str) -> Path:
    return Path(out_dir) / "tables" / f"{robot}.npy"


def params_path(out_dir: str | Path, robot: str) -> Path:
    """Where a function learner's final parameters are: ``params/<robot>.npy``."""
    return Path(out_dir) / "params" / f"{robot}.npy"


def learnt_path(out_dir: str | Path, robot: str) -> Path | None:
    """The robot's saved table, else its saved parameters, else None."""
    for p in (table_path(out_dir, robot), params_path(out_dir, robot)):
        if p.is_file():
            return p
    return None


def _relative(npy: Path) -> str:
    return f"{npy.parent.name}/{npy.name}"


def _side_files(npy: Path) -> list[Path]:
    """``.npy``, ``.visits.npy`` and ``.json`` of a table."""
    return [npy, npy.with_suffix(".visits.npy"), npy.with_suffix(".json")]


def _read_table(npy: Path, params: bool = False) -> np.ndarray:
    """The table of ``npy``, checked whole: a finite-shape 2-D float array (``params``: a
    1-D float vector); its ``.visits.npy`` and ``.json`` (when present) readable.

    Raises
    ------
    OSError, ValueError, EOFError
        A torn or foreign file.
    """
    q = np.load(npy, allow_pickle=False)
    if params and (q.ndim != 1 or q.dtype.kind != "f"):
        raise ValueError(f"not a parameter vector: {q.dtype} array of shape {q.shape}")
    if not params and (q.ndim != 2 or q.dtype.kind != "f"):
        raise ValueError(f"not a Q-table: {q.dtype} array of shape {q.shape}")
    visits = npy.with_suffix(".visits.npy")
    if visits.is_file() and np.load(visits, allow_pickle=False).shape != q.shape:
        raise ValueError(f"{visits.name} does not have the table's shape {q.shape}")
    side = npy.with_suffix(".json")
    if side.is_file():
        json.loads(side.read_text(encoding="utf-8"))
    return q


def table_sum(out_dir: str | Path, robot: str) -> float | None:
    """Sum of ``tables/<robot>.npy``, or of a function learner's ``params/<robot>.npy`` (None:
    no such file, or one that cannot be read)."""
    p = learnt_path(out_dir, robot)
    if p is None:
        return None
    try:
        return float(np.load(p, allow_pickle=False).sum())
    except _UNREADABLE:
        return None


def set_aside_unreadable(out_dir: str | Path, robots: list[str]) -> dict[str, str]:
    """Move every torn or unreadable ``tables/<robot>.npy`` (with its ``.visits.npy`` and
    ``.json``) or ``params/<robot>.npy`` (with its ``.json``) to ``<name>.torn``; return
    robot -> what was wrong."""
    found: dict[str, str] = {}
    for rid in robots:
        npy = learnt_path(out_dir, rid)
        if npy is None:
            continue
        try:
            _read_table(npy, params=npy == params_path(out_dir, rid))
        except _UNREADABLE as exc:
            found[rid] = f"{_relative(npy)} unreadable ({type(exc).__name__}: {exc})"
            for f in _side_files(npy):
                if f.is_file():
                    os.replace(f, f.with_name(f.name + ".torn"))
    return found


def keep_checkpoints(out_dir: str | Path, robots: list[str]) -> list[str]:
    """For every robot without ``tables/<robot>.npy`` (a function learner: without
    ``params/<robot>.npy``), write it (and ``.visits.npy``) from ``checkpoint/<robot>.npy``,
    with a ``.json`` that says so (its iteration and shares), each file atomically. Returns
    the robots whose table (parameters) came from a checkpoint."""
    out = Path(out_dir)
    kept = []
    for rid in robots:
        if learnt_path(out, rid) is not None or not (out / "checkpoint" / f"{rid}.npy").is_file():
            continue
        try:
            cp = load_checkpoint(out / "checkpoint", rid)
        except _UNREADABLE:
            continue
        if cp.params is not None:
            target = params_path(out, rid)
            atomic_write(target, _npy_bytes(cp.params))
        else:
            target = table_path(out, rid)
            assert cp.q is not None and cp.visits is not None, "a table's checkpoint has both"
            for path, array in ((target.with_suffix(".visits.npy"), cp.visits), (target, cp.q)):
                atomic_write(path, _npy_bytes(array))
        what = "parameters" if cp.params is not None else "table"
        doc = {"source": f"checkpoint/{rid}.npy (the run was interrupted, or its final {what} "
                         "was missing or torn)",
               "iteration": cp.iteration, "shares": cp.shares, "shape": list(cp.learnt.shape),
               "dtype": "float64"}
        atomic_write(target.with_suffix(".json"), (json.dumps(doc, indent=2) + "\n").encode())
        kept.append(rid)
    return kept


def _npy_bytes(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, array, allow_pickle=False)
    return buf.getvalue()


def table_problems(unreadable: dict[str, str], kept: list[str],
                   out_dir: str | Path) -> dict[str, str]:
    """robot -> one line for the summary: what was wrong with its final table and what is in
    ``tables/`` (``params/``) instead (its last complete checkpoint, at iteration N, or
    nothing)."""
    lines = {}
    for rid, why in unreadable.items():
        torn = table_path(out_dir, rid)
        if not torn.with_name(torn.name + ".torn").is_file():
            torn = params_path(out_dir, rid)
        if rid in kept:
            try:
                it = json.loads(torn.with_suffix(".json")
                                .read_text(encoding="utf-8"))["iteration"]
                instead = f"its last complete checkpoint is used (iteration {it})"
            except (*_UNREADABLE, KeyError):
                instead = "its last complete checkpoint is used"
        else:
            instead = "no complete checkpoint either: no final table"
        lines[rid] = f"{why}; set aside as {_relative(torn)}.torn; {instead}"
    return lines


def final_tables(out_dir: str | Path, robots: list[str]) -> tuple[list[str], dict[str, str]]:
    """Make ``tables/`` whole at the end of a run: torn tables set aside, a missing or torn
    table replaced by the robot's last complete checkpoint. Returns (robots whose table came
    from a checkpoint, robot -> the problem with its final table, for the summary)."""
    unreadable = set_aside_unreadable(out_dir, robots)
    kept = keep_checkpoints(out_dir, robots)
    return kept, table_problems(unreadable, kept, out_dir)
