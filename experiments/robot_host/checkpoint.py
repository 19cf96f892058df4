"""A robot's checkpoint: its learning state, written atomically at every share and at the end.

``checkpoint/<robot>.npy`` is the checkpoint itself, one file so that it is replaced as a
whole: a NumPy structured scalar with fields

=====================  ===================  ==============================================
field                  dtype, shape         meaning
=====================  ===================  ==============================================
``q``                  float64, (S, A)      the Q-table (tabular learners)
``visits``             int64, (S, A)        update counts per state-action pair (tabular)
``params``             float64, (P,)        the parameter vector (function learners, instead
                                            of ``q`` and ``visits``)
``iteration``          int64                iterations done
``shares``             int64                shares applied
``learner_t``          int64                the learner's update count (its epsilon clock)
``cumulative_reward``  float64
``collisions``         int64
``respawns``           int64
=====================  ===================  ==============================================

(``np.load(path)["q"]`` is the table, ``np.load(path)["params"]`` the vector). A function
learner's checkpoint holds its parameters and counters only: resuming one (:func:`restore_trainer`)
restores the parameters (``dqn``: into the online and the target network), the epsilon clock
and the counters; the optimiser's state (Adam moments), the replay buffer and the count of
gradient steps start afresh, so a resumed ``dqn`` learns again only once its buffer holds
``learning_starts`` new transitions.

``checkpoint/<robot>.json`` beside it describes it for
people and tools (robot, experiment, iteration, shares, the sha256 of the table or vector, the
time); it is written after the ``.npy`` and is not read back. Each file is written to a
temporary name, flushed, fsynced and renamed over the old one, then the directory is fsynced: a
crash leaves either the old or the new checkpoint, never a torn one.

The final tables (``tables/<robot>.npy``, ``.json``, ``.visits.npy``, in the format of
:mod:`dfrl.robots.tables`) are replaced the same way by :func:`save_table_atomically`, a
function learner's final parameters (``params/<robot>.npy`` + ``.json``, format
``dfrl-params/2``) by :func:`save_params_atomically`.
"""

from __future__ import annotations

import io
import json
import os
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dfrl.experiments.robot_host.files import table_digest

__all__ = [
    "Checkpoint",
    "atomic_write",
    "save_checkpoint",
    "load_checkpoint",
    "checkpoint_of",
    "restore_trainer",
    "save_table_atomically",
    "save_params_atomically",
    "save_learnt_atomically",
]


@dataclass
class Checkpoint:
    """A robot's learning state (see the module doc for the fields): ``q`` and ``visits`` of a
    tabular learner, or ``params`` of a function learner (the others None)."""

    q: np.ndarray | None
    visits: np.ndarray | None
    iteration: int
    shares: int
    learner_t: int = 0
    cumulative_reward: float = 0.0
    collisions: int = 0
    respawns: int = 0
    params: np.ndarray | None = None

    @property
    def learnt(self) -> np.ndarray:
        """What was learnt: the Q-table, or the parameter vector."""
        return self.params if self.params is not None else self.q  # type: ignore[return-value]


_SCALARS: tuple[tuple[str, str], ...] = (
    ("iteration", "<i8"),
    ("shares", "<i8"),
    ("learner_t", "<i8"),
    ("cumulative_reward", "<f8"),
    ("collisions", "<i8"),
    ("respawns", "<i8"),
)


def atomic_write(path: Path, data: bytes) -> None:
    """Replace ``path`` by ``data`` atomically: temporary name, fsync, rename, fsync dir."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view) :]
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, path)
    _fsync_dir(path.parent)


def _fsync_dir(directory: Path) -> None:
    dfd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(dfd)
    finally:
        os.close(dfd)


def save_table_atomically(trainer: Any, path: str | Path) -> Path:
    """``trainer.save_table(path)`` (``.npy``, ``.visits.npy``, ``.json``; the format of
    :func:`dfrl.robots.tables.save_table`), each file replaced atomically: written in a
    temporary folder beside ``path``, fsynced, renamed over the old one (the ``.json`` last),
    the folder fsynced. A kill leaves the old files or the new ones, never a torn table.
    Returns the ``.npy`` path."""
    return _save_atomically(trainer.save_table, path)


def save_params_atomically(trainer: Any, path: str | Path) -> Path:
    """``trainer.save_params(path)`` (``.npy`` + ``.json``; the format of
    :func:`dfrl.robots.tables.save_params`), replaced atomically as
    :func:`save_table_atomically` does. Returns the ``.npy`` path."""
    return _save_atomically(trainer.save_params, path)


def save_learnt_atomically(trainer: Any, out_dir: str | Path, robot: str) -> Path:
    """The final save of a robot: ``tables/<robot>`` for a tabular learner, ``params/<robot>``
    for a function learner (``trainer.learner_kind``), atomically. Returns the ``.npy`` path."""
    if getattr(trainer, "learner_kind", "tabular") == "function":
        return save_params_atomically(trainer, Path(out_dir) / "params" / robot)
    return save_table_atomically(trainer, Path(out_dir) / "tables" / robot)


def _save_atomically(save: Any, path: str | Path) -> Path:
    target = Path(path)
    folder = target.parent
    folder.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=folder, prefix=f".{target.name}.tmp-") as tmp:
        written = Path(save(Path(tmp) / target.name))
        files = sorted(Path(tmp).iterdir(), key=lambda f: (f.suffix == ".json", f.name))
        for f in files:
            fd = os.open(f, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
        for f in files:
            os.replace(f, folder / f.name)
    _fsync_dir(folder)
    return folder / written.name


def paths(directory: Path, robot: str) -> tuple[Path, Path]:
    """(``<robot>.npy``, ``<robot>.json``) in ``directory``."""
    return directory / f"{robot}.npy", directory / f"{robot}.json"


def save_checkpoint(
    directory: Path, robot: str, cp: Checkpoint, meta: dict[str, Any] | None = None
) -> Path:
    """Write ``cp`` as ``directory/<robot>.npy`` (+ ``.json``) atomically; return the .npy."""
    if cp.params is not None:
        q = np.ascontiguousarray(cp.params, dtype=np.float64)
        if q.ndim != 1:
            raise ValueError(f"checkpoint parameters: shape {q.shape}, not a vector")
        dtype = np.dtype([("params", "<f8", q.shape), *_SCALARS])
        rec = np.zeros((), dtype=dtype)
        rec["params"] = q
        fields, digest_key = "params", "params_sha256"
    else:
        q = np.ascontiguousarray(cp.q, dtype=np.float64)
        visits = np.ascontiguousarray(cp.visits, dtype=np.int64)
        if q.ndim != 2 or visits.shape != q.shape:
            raise ValueError(f"checkpoint tables: q {q.shape}, visits {visits.shape}")
        dtype = np.dtype([("q", "<f8", q.shape), ("visits", "<i8", q.shape), *_SCALARS])
        rec = np.zeros((), dtype=dtype)
        rec["q"], rec["visits"] = q, visits
        fields, digest_key = "q, visits", "q_sha256"
    for name, _ in _SCALARS:
        rec[name] = getattr(cp, name)
    buf = io.BytesIO()
    np.save(buf, rec, allow_pickle=False)
    npy, side = paths(directory, robot)
    atomic_write(npy, buf.getvalue())
    info = dict(
        meta or {},
        robot=robot,
        iteration=int(cp.iteration),
        shares=int(cp.shares),
        shape=list(q.shape),
        **{digest_key: table_digest(q)},
        wall_time=time.time(),
        format=f"numpy structured scalar: {fields}, " + ", ".join(n for n, _ in _SCALARS),
    )
    atomic_write(side, (json.dumps(info, indent=2) + "\n").encode("utf-8"))
    return npy


def load_checkpoint(directory: Path, robot: str) -> Checkpoint:
    """Read ``directory/<robot>.npy``.

    Raises
    ------
    FileNotFoundError
        No checkpoint.
    ValueError
        Not a checkpoint file.
    """
    npy, _ = paths(directory, robot)
    rec = np.load(npy, allow_pickle=False)
    names = rec.dtype.names or ()
    function = "params" in names
    learnt = {"params"} if function else {"q", "visits"}
    missing = {*learnt, *(n for n, _ in _SCALARS)} - set(names)
    if rec.shape != () or missing:
        raise ValueError(f"{npy} is not a robot checkpoint (missing {sorted(missing)})")
    return Checkpoint(
        q=None if function else np.array(rec["q"], dtype=np.float64),
        visits=None if function else np.array(rec["visits"], dtype=np.int64),
        params=np.array(rec["params"], dtype=np.float64) if function else None,
        iteration=int(rec["iteration"]),
        shares=int(rec["shares"]),
        learner_t=int(rec["learner_t"]),
        cumulative_reward=float(rec["cumulative_reward"]),
        collisions=int(rec["collisions"]),
        respawns=int(rec["respawns"]),
    )


def checkpoint_of(trainer: Any, shares: int) -> Checkpoint:
    """The learning state of a :class:`dfrl.robots.training.Trainer` now (a function learner:
    its parameters instead of a table)."""
    function = getattr(trainer, "learner_kind", "tabular") == "function"
    return Checkpoint(
        q=None if function else np.array(trainer.q_table),
        visits=None if function else np.array(trainer.visits),
        params=trainer.params if function else None,
        iteration=int(trainer.iteration),
        shares=int(shares),
        learner_t=int(trainer.learner.t),
        cumulative_reward=float(trainer.cumulative_reward),
        collisions=int(trainer.collisions),
        respawns=int(trainer.respawns),
    )


def restore_trainer(trainer: Any, cp: Checkpoint) -> None:
    """Put a fresh trainer in the state of ``cp`` (table and visits, or parameters; counters,
    epsilon clock; see the module doc for what a function learner does not get back).

    The simulation itself starts a new episode: the robot's pose is not checkpointed.

    Raises
    ------
    ValueError
        The checkpoint's table does not have the trainer's shape, or holds a table for a
        function learner (or parameters for a tabular one), or parameters of another size.
    """
    function = getattr(trainer, "learner_kind", "tabular") == "function"
    if function != (cp.params is not None):
        held = "parameters" if cp.params is not None else "a Q-table"
        raise ValueError(
            f"the checkpoint holds {held}, this robot's learner "
            f"({trainer.config.algo}) {'has parameters' if function else 'a table'}"
        )
    if cp.params is not None:  # a function learner's (checked just above)
        trainer.set_params(cp.params)
    else:
        if cp.q is None:
            raise ValueError("the checkpoint holds neither a table nor parameters")
        if cp.q.shape != trainer.q_table.shape:
            raise ValueError(
                f"the checkpoint's table has shape {cp.q.shape}, this robot's "
                f"{trainer.q_table.shape}"
            )
        trainer.set_q_table(cp.q)
        trainer.visits[...] = cp.visits
    trainer.learner.t = cp.learner_t
    trainer.iteration = cp.iteration
    trainer.cumulative_reward = cp.cumulative_reward
    trainer.collisions = cp.collisions
    trainer.respawns = cp.respawns
