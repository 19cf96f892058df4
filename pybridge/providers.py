"""What a robot offers the bridge, and providers without a robot.

A robot offers its Q-table (:class:`TableProvider`: tabular learners), its learnable
parameters as one flat float vector with a layout (:class:`ParamsProvider`: function
learners, and tabular ones that also expose their table that way), or both.

The bridge validates a write once, where it enters Python (shape or layout, size, finite
values; see :mod:`dfrl.pybridge.serving`), so a provider's ``write_table`` always receives a
float64 array of the registered shape with finite entries, and ``set_params`` a float64
vector of the registered layout's size with finite entries.

A Q-table is read and written with one verb pair along its whole path (README, "Words"):
``read_table()`` / ``write_table(table, origin)`` here, the bridge's ``read_table`` /
``write_table`` requests, ``robot_bridge:read_table/3`` / ``write_table/3`` in Prolog.
:func:`read_table` and :func:`write_table` are the one place a provider is read and written;
they still serve a provider written before the verb pair (deprecated: a ``q_table``
property, ``set_q_table(table)`` or ``set_q_table_from(table, origin)``, and an optional
``table_read()`` note).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, Protocol, runtime_checkable

import numpy as np

__all__ = [
    "TableProvider",
    "ParamsProvider",
    "StaticTable",
    "StaticParams",
    "Layout",
    "check_layout",
    "layout_size",
    "read_table",
    "write_table",
]

#: A parameter layout: (name, shape) per block of the flat vector, in order; the vector is
#: the blocks' row-major values one after the other.
Layout = list[tuple[str, tuple[int, ...]]]


@runtime_checkable
class TableProvider(Protocol):
    """What a robot offers to the bridge.

    ``read_table()`` : an agent's read: float64 ndarray, shape (n_states, n_actions)
    ``visits`` : int64 ndarray, shape (n_states, n_actions)
    ``write_table(table, origin)`` : an agent's write: replace the table with a float64 array
    of the same shape (already validated by the bridge: registered shape, finite entries);
    ``origin`` holds the write's origin options (``round``, ``agent``, ``epoch``, ...)
    """

    def read_table(self) -> np.ndarray: ...

    @property
    def visits(self) -> np.ndarray: ...

    def write_table(self, table: np.ndarray, origin: Mapping[str, Any]) -> None: ...


def read_table(provider: Any) -> np.ndarray:
    """An agent's read of ``provider``'s Q-table: ``provider.read_table()``; of a provider
    written before the verb pair (deprecated), its ``q_table``, after which its ``table_read()``
    note, if it has one, is called. Of a class that defines both, the name its most derived
    class defines is used (a subclass of before overriding ``q_table`` keeps its meaning)."""
    if _newest(provider, ("read_table", "q_table")) == "read_table":
        return np.asarray(provider.read_table())
    table = np.asarray(provider.q_table)
    if getattr(type(provider), "table_read", None) is not None:
        provider.table_read()
    return table


def write_table(provider: Any, table: np.ndarray, origin: Mapping[str, Any]) -> None:
    """An agent's write of a validated ``table`` into ``provider``:
    ``provider.write_table(table, origin)``; of a provider written before the verb pair
    (deprecated), ``set_q_table_from(table, origin)``, else ``set_q_table(table)``; the name its
    most derived class defines is used, as in :func:`read_table`."""
    name = _newest(provider, ("write_table", "set_q_table_from", "set_q_table"))
    if name == "set_q_table":
        provider.set_q_table(table)
    else:
        getattr(provider, name)(table, origin)


def _newest(provider: Any, names: tuple[str, ...]) -> str:
    """Of ``names`` (in order of preference), the one defined by the most derived class of
    ``provider`` that defines any; the last name if none does."""
    for cls in type(provider).__mro__:
        for name in names:
            if name in vars(cls):
                return name
    return names[-1]


@runtime_checkable
class ParamsProvider(Protocol):
    """What a robot whose parameters agents federate offers to the bridge.

    ``params`` : float64 ndarray, shape (layout_size(param_layout),); a plain getter
    ``param_layout`` : :data:`Layout`, fixed while the robot is registered
    ``set_params(vec)`` : replace the parameters (already validated by the bridge:
    float64, the layout's size, finite entries)
    ``samples`` : int >= 0, the steps learnt from (the FedAvg weight)
    ``learner_kind`` : ``"tabular"`` or ``"function"``
    """

    @property
    def params(self) -> np.ndarray: ...

    @property
    def param_layout(self) -> Layout: ...

    def set_params(self, vec: np.ndarray) -> None: ...

    @property
    def samples(self) -> int: ...

    @property
    def learner_kind(self) -> str: ...


class LearnerProvider(TableProvider, ParamsProvider, Protocol):
    """A robot that offers both its Q-table (a function learner: its grid view) and its
    parameters: a :class:`dfrl.robots.training.Trainer`, :class:`StaticParams`."""


def check_layout(layout: Sequence[tuple[str, Sequence[int]]]) -> Layout:
    """``layout`` as a :data:`Layout` of plain ``str`` and ``int``, checked.

    Raises
    ------
    ValueError
        Not a non-empty sequence of (name, shape) with distinct non-empty names and
        non-negative integer dimensions, or a layout of size 0.
    """
    out: Layout = []
    try:
        items = list(layout)
    except TypeError:
        raise ValueError(f"a layout is a list of (name, shape), got {layout!r:.80}") from None
    for item in items:
        if not (isinstance(item, (tuple, list)) and len(item) == 2):
            raise ValueError(f"a layout entry is (name, shape), got {item!r:.80}")
        name, shape = item
        if not (isinstance(name, str) and name):
            raise ValueError(f"a layout name is a non-empty str, got {name!r:.80}")
        dims = tuple(shape) if isinstance(shape, (tuple, list)) else None
        if dims is None or not all(
            isinstance(d, (int, np.integer)) and not isinstance(d, bool) and d >= 0 for d in dims
        ):
            raise ValueError(f"the shape of {name!r} is a tuple of integers >= 0, got {shape!r}")
        out.append((name, tuple(int(d) for d in dims)))
    names = [n for n, _ in out]
    if len(set(names)) != len(names):
        raise ValueError(f"layout names repeat: {names}")
    if layout_size(out) < 1:
        raise ValueError("a layout holds at least one parameter")
    return out


def layout_size(layout: Layout) -> int:
    """The number of floats in a vector of ``layout`` (the product of each shape, summed)."""
    return sum(math.prod(shape) for _, shape in layout)


class StaticTable:
    """A table provider without a robot: a random Q-table that only agents change.

    For benchmarks and tests. The same shape and seed give the same tables.

    Parameters
    ----------
    shape : (int, int)
        (n_states, n_actions), both positive.
    seed : int
        Seeds the Q-values (standard normal) and the visit counts (integers in [0, 100)).

    Attributes
    ----------
    sets : int
        How many times :meth:`write_table` replaced the table.
    """

    def __init__(self, shape: tuple[int, int], seed: int = 0) -> None:
        n_states, n_actions = (int(x) for x in shape)
        if n_states < 1 or n_actions < 1:
            raise ValueError(f"a table shape is two positive integers, got {tuple(shape)}")
        rng = np.random.default_rng(seed)
        self._q = rng.standard_normal((n_states, n_actions))
        self._visits = rng.integers(0, 100, (n_states, n_actions), dtype=np.int64)
        self.sets = 0

    @property
    def shape(self) -> tuple[int, int]:
        """(n_states, n_actions)."""
        return (int(self._q.shape[0]), int(self._q.shape[1]))

    @property
    def q_table(self) -> np.ndarray:
        """A copy of the Q-table, float64, shape (n_states, n_actions)."""
        return self._q.copy()

    @property
    def visits(self) -> np.ndarray:
        """A copy of the visit counts, int64, shape (n_states, n_actions)."""
        return self._visits.copy()

    def read_table(self) -> np.ndarray:
        """A copy of the Q-table (an agent's read)."""
        return self.q_table

    def write_table(self, table: np.ndarray, origin: Mapping[str, Any] | None = None) -> None:
        """Replace the Q-table with a float64 copy of ``table`` (shape (n_states, n_actions))."""
        self._q = np.array(table, dtype=np.float64)
        self.sets += 1

    def set_q_table(self, table: np.ndarray) -> None:
        """Deprecated name of :meth:`write_table`."""
        self.write_table(table)

    def __repr__(self) -> str:
        return f"<StaticTable shape={self.shape} sets={self.sets}>"


class StaticParams:
    """A params provider without a robot: a random parameter vector only agents change.

    For benchmarks and tests; a real object with the :class:`ParamsProvider` contract. The
    same layout, seed and samples give the same vectors.

    Parameters
    ----------
    layout : Layout
        (name, shape) per block, e.g. ``[("w1", (4, 16)), ("b1", (16,))]``.
    seed : int
        Seeds the values (standard normal).
    samples : int
        The steps this "learner" has learnt from (the FedAvg weight), >= 0.
    learner_kind : str
        ``"function"`` (default) or ``"tabular"``.

    Attributes
    ----------
    sets : int
        How many times :meth:`set_params` replaced the vector.
    """

    def __init__(
        self,
        layout: Sequence[tuple[str, Sequence[int]]],
        seed: int = 0,
        samples: int = 0,
        learner_kind: str = "function",
    ) -> None:
        self._layout = check_layout(layout)
        if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 0:
            raise ValueError(f"samples is an integer >= 0, got {samples!r}")
        if learner_kind not in ("tabular", "function"):
            raise ValueError(f"learner_kind is 'tabular' or 'function', got {learner_kind!r}")
        self._kind = learner_kind
        self._vec = np.random.default_rng(seed).standard_normal(layout_size(self._layout))
        self._samples = int(samples)
        self.sets = 0

    @property
    def params(self) -> np.ndarray:
        """A copy of the parameters, float64, shape (layout_size(param_layout),)."""
        return self._vec.copy()

    @property
    def param_layout(self) -> Layout:
        """The layout given at construction."""
        return list(self._layout)

    @property
    def samples(self) -> int:
        """The FedAvg weight given at construction."""
        return self._samples

    @property
    def learner_kind(self) -> str:
        """``"function"`` or ``"tabular"``."""
        return self._kind

    def set_params(self, vec: np.ndarray) -> None:
        """Replace the parameters with a float64 copy of ``vec``.

        Raises
        ------
        ValueError
            ``vec`` is not 1-D of the layout's size with finite entries.
        """
        arr = np.asarray(vec, dtype=np.float64)
        if arr.shape != self._vec.shape or not np.isfinite(arr).all():
            raise ValueError(
                f"parameters of shape {self._vec.shape} with finite entries "
                f"expected, got shape {arr.shape}"
            )
        self._vec = arr.copy()
        self.sets += 1

    def __repr__(self) -> str:
        return f"<StaticParams size={self._vec.size} samples={self._samples} sets={self.sets}>"


#: what a provider needs to offer its parameters (ParamsProvider, without learner_kind)
_PARAMS_ATTRS = ("params", "param_layout", "set_params", "samples")


def provider_offer(
    provider: Any, shape: Sequence[int] | None = None, learner: str | None = None
) -> tuple[str, tuple[int, int] | None, Layout | None]:
    """What ``provider`` offers agents: ``(learner, table_shape, layout)``, checked.

    ``learner`` defaults to the provider's ``learner_kind``, else ``"tabular"``. A tabular
    learner needs ``read_table``, ``visits`` and ``write_table`` (or, deprecated, ``q_table``
    and ``set_q_table`` for the first and last) and has a table shape (``shape``, or read once
    from ``q_table``, else ``read_table()``); a function learner needs the parameter
    attributes and has a table shape only when one is given, for a table view of its Q-function
    (:class:`dfrl.robots.grid_view.GridView`: a heterogeneous federation), which then needs
    the table attributes too. ``layout`` is the checked parameter layout when the provider
    offers parameters, else None.

    Raises
    ------
    TypeError
        The provider lacks what its learner kind must offer.
    ValueError
        A bad shape, layout or learner kind.
    """
    names = dir(provider)  # (hasattr would read the properties)
    if learner is None:
        learner = str(provider.learner_kind) if "learner_kind" in names else "tabular"
    if learner not in ("tabular", "function"):
        raise ValueError(f"learner is 'tabular' or 'function', got {learner!r}")
    table_shape: tuple[int, int] | None = None
    if learner == "tabular":
        for attr in _table_attrs(names):
            if attr not in names:
                raise TypeError(f"provider has no {attr!r}")
        table_shape = _table_shape(provider, shape)
    else:
        for attr in _PARAMS_ATTRS:
            if attr not in names:
                raise TypeError(f"provider of a function learner has no {attr!r}")
        if shape is not None:  # a table view of its Q-function (robots/grid_view.py)
            for attr in _table_attrs(names):
                if attr not in names:
                    raise ValueError(
                        f"a function learner registered with a table shape offers "
                        f"a table view (q_table, visits, set_q_table); no {attr!r}"
                    )
            table_shape = _table_shape(provider, shape)
    offers_params = all(a in names for a in _PARAMS_ATTRS)
    layout = check_layout(provider.param_layout) if offers_params else None
    return learner, table_shape, layout


def _table_attrs(names: list[str]) -> tuple[str, ...]:
    """What a table provider needs: the verb pair, or (deprecated) the names of before."""
    if "read_table" in names or "write_table" in names:
        return ("read_table", "visits", "write_table")
    return ("q_table", "visits", "set_q_table")


def _table_shape(provider: Any, shape: Sequence[int] | None) -> tuple[int, int]:
    if shape is None:  # q_table: a plain getter, where it has one
        table = provider.q_table if "q_table" in dir(provider) else provider.read_table()
        dims = tuple(np.shape(table))
    else:
        dims = tuple(shape)
    if len(dims) != 2 or not all(isinstance(d, (int, np.integer)) and d > 0 for d in dims):
        raise ValueError(f"a table shape is two positive integers, got {dims}")
    return (int(dims[0]), int(dims[1]))
