"""Q-table files: ``NAME.npy`` (the array) + ``NAME.json`` (what it means) [+ ``NAME.visits.npy``].

The ``.npy`` holds the float64 array of shape ``(n_states, n_actions)``. The JSON sidecar holds
``format`` (``"dfrl-qtable/2"``; ``/1`` files, which say ``algorithm``, still load), ``shape``,
``dtype``, ``algo``, ``arena``, ``seed``, ``iterations``, ``actions`` (names by column index),
``state`` (the discretisation, see :meth:`dfrl.robots.state.Discretiser.describe`) and free
``extra`` fields. The optional
``NAME.visits.npy`` holds the int64 update counts of each entry. A sidecar written before the
learner's name was called ``algo`` everywhere (format ``/1``) names it ``algorithm``; it still
loads, and a dfrl that knows only ``/1`` refuses a ``/2`` file by its format.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dfrl.robots.learners import validate_table

#: the sidecar's format written now; /2 names the learner ``algo`` (/1 said ``algorithm``), so a
#: dfrl that knows only /1 refuses a new file by its format instead of failing on a missing key
TABLE_FORMAT = "dfrl-qtable/2"
#: the formats read: this one and the one before
TABLE_FORMATS = ("dfrl-qtable/1", TABLE_FORMAT)


@dataclass(frozen=True)
class TableMeta:
    """What a saved Q-table means.

    Attributes
    ----------
    algo : str
        The learner's registered name (``"qlearning"``, ``"sarsa"``).
    arena : str
        Arena name.
    seed : int
    iterations : int
        Control steps of learning behind the table.
    actions : list[str]
        Action names, index-aligned with the table's columns.
    state : dict
        Discretisation description (rows).
    extra : dict
        Anything else worth keeping (JSON-serialisable).
    """

    algo: str
    arena: str
    seed: int
    iterations: int
    actions: list[str]
    state: dict[str, Any]
    extra: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class LoadedTable:
    """A table read back by :func:`load_table`.

    Attributes
    ----------
    q : np.ndarray, shape (n_states, n_actions), float64
    meta : TableMeta
    visits : np.ndarray or None, shape (n_states, n_actions), int64
    """

    q: np.ndarray
    meta: TableMeta
    visits: np.ndarray | None


def _paths(path: str | Path) -> tuple[Path, Path, Path]:
    base = Path(path)
    if base.suffix == ".npy":
        base = base.with_suffix("")
    elif base.suffix == ".json":
        base = base.with_suffix("")
    return (
        base.with_name(base.name + ".npy"),
        base.with_name(base.name + ".json"),
        base.with_name(base.name + ".visits.npy"),
    )


def save_table(
    path: str | Path, q: np.ndarray, meta: TableMeta, visits: np.ndarray | None = None
) -> Path:
    """Write a Q-table and its sidecar JSON (and visits when given).

    Parameters
    ----------
    path : str or Path
        ``DIR/NAME`` or ``DIR/NAME.npy``.
    q : np.ndarray, shape (n_states, n_actions)
    meta : TableMeta
    visits : np.ndarray, shape (n_states, n_actions), optional

    Returns
    -------
    Path
        The ``.npy`` path.
    """
    q = validate_table(q, np.shape(q))
    if q.ndim != 2:
        raise ValueError(f"a Q-table is 2-D (n_states, n_actions), got shape {q.shape}")
    if len(meta.actions) != q.shape[1]:
        raise ValueError(f"{len(meta.actions)} action names for {q.shape[1]} table columns")
    npy, js, vis = _paths(path)
    npy.parent.mkdir(parents=True, exist_ok=True)
    np.save(npy, q)
    doc = {"format": TABLE_FORMAT, "shape": list(q.shape), "dtype": "float64", **asdict(meta)}
    if visits is not None:
        visits = np.asarray(visits, dtype=np.int64)
        if visits.shape != q.shape:
            raise ValueError(f"visits shape {visits.shape} differs from table shape {q.shape}")
        np.save(vis, visits)
        doc["visits_file"] = vis.name
    js.write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    return npy


def load_table(path: str | Path) -> LoadedTable:
    """Read a table written by :func:`save_table`, checking it against its sidecar.

    Raises
    ------
    ValueError
        Missing sidecar, unknown format, or an array that does not match the recorded shape.
    """
    npy, js, vis = _paths(path)
    if not js.exists():
        raise ValueError(f"{npy}: missing sidecar {js.name} describing the table")
    doc = json.loads(js.read_text(encoding="utf-8"))
    if doc.get("format") not in TABLE_FORMATS:
        raise ValueError(
            f"{js}: unknown table format {doc.get('format')!r}, expected one of "
            f"{', '.join(TABLE_FORMATS)}"
        )
    q = validate_table(np.load(npy, allow_pickle=False), tuple(doc["shape"]))
    meta = TableMeta(
        algo=_algo(doc),
        **{k: doc[k] for k in ("arena", "seed", "iterations", "actions", "state")},
        extra=doc.get("extra", {}),
    )
    visits = None
    if doc.get("visits_file"):
        visits = np.load(vis, allow_pickle=False).astype(np.int64)
        if visits.shape != q.shape:
            raise ValueError(f"{vis}: shape {visits.shape} differs from the table's {q.shape}")
    return LoadedTable(q=q, meta=meta, visits=visits)


# -- parameter files (function-approximation learners) -------------------------------------
#: as TABLE_FORMAT: /2 names the learner ``algo``, /1 ``algorithm``; both are read
PARAMS_FORMAT = "dfrl-params/2"
PARAMS_FORMATS = ("dfrl-params/1", PARAMS_FORMAT)


@dataclass(frozen=True)
class ParamsMeta:
    """What a saved parameter vector means (``linear``, ``dqn``).

    Attributes
    ----------
    algo : str
        The learner's registered name.
    arena : str
    seed : int
    iterations : int
        Control steps of learning behind the parameters.
    actions : list[str]
        Action names, index-aligned with the model's outputs.
    layout : list of [name, shape]
        The arrays the flat vector concatenates, in order, each in C order.
    model : dict
        The learner's own configuration (feature map or network), as in ``config.json``.
    extra : dict
    """

    algo: str
    arena: str
    seed: int
    iterations: int
    actions: list[str]
    layout: list[tuple[str, tuple[int, ...]]]
    model: dict[str, Any]
    extra: dict[str, Any] = field(default_factory=dict)


def save_params(path: str | Path, vec: np.ndarray, meta: ParamsMeta) -> Path:
    """Write ``NAME.npy`` (the flat float64 vector) and ``NAME.json`` (format, size, meta).

    Raises
    ------
    ValueError
        The vector does not fit ``meta.layout`` or has a non-finite entry.
    """
    from dfrl.robots.approx import validate_params

    layout = [(str(n), tuple(int(d) for d in s)) for n, s in meta.layout]
    arr = validate_params(vec, layout)
    npy, js, _ = _paths(path)
    npy.parent.mkdir(parents=True, exist_ok=True)
    np.save(npy, arr)
    doc = {
        "format": PARAMS_FORMAT,
        "size": int(arr.shape[0]),
        "dtype": "float64",
        **asdict(meta),
        "layout": [[n, list(s)] for n, s in layout],
    }
    js.write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    return npy


@dataclass(frozen=True)
class LoadedParams:
    """A parameter vector read back by :func:`load_params`."""

    params: np.ndarray
    meta: ParamsMeta


def load_params(path: str | Path) -> LoadedParams:
    """Read a parameter vector and its sidecar; check format, layout and values.

    Raises
    ------
    ValueError
        Not a parameter file, or the vector does not fit its layout.
    """
    from dfrl.robots.approx import validate_params

    npy, js, _ = _paths(path)
    doc = json.loads(js.read_text(encoding="utf-8"))
    if doc.get("format") not in PARAMS_FORMATS:
        raise ValueError(
            f"{js}: format {doc.get('format')!r}, expected one of {', '.join(PARAMS_FORMATS)}"
        )
    layout = [(str(n), tuple(int(d) for d in s)) for n, s in doc["layout"]]
    vec = validate_params(np.load(npy, allow_pickle=False), layout)
    meta = ParamsMeta(
        algo=_algo(doc),
        arena=doc["arena"],
        seed=doc["seed"],
        iterations=doc["iterations"],
        actions=list(doc["actions"]),
        layout=layout,
        model=dict(doc.get("model", {})),
        extra=dict(doc.get("extra", {})),
    )
    return LoadedParams(params=vec, meta=meta)


def _algo(doc: dict[str, Any]) -> str:
    """The learner's name in a sidecar: key ``algo``, or ``algorithm`` in one written before."""
    return doc["algo"] if "algo" in doc else doc["algorithm"]


def sidecar_format(path: str | Path) -> str | None:
    """The ``format`` in the JSON sidecar of a saved table or parameter file (``NAME.npy``,
    ``NAME.json`` or ``NAME``); None when there is none or it cannot be read."""
    _, js, _ = _paths(path)
    try:
        return json.loads(js.read_text(encoding="utf-8")).get("format")
    except (OSError, ValueError, AttributeError):
        return None
