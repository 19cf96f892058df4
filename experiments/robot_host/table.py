"""The provider the robot process registers with the bridge: its table (and parameters), with
share bookkeeping.

The table itself (a :class:`dfrl.robots.training.Trainer`, or a static robot's
:class:`dfrl.pybridge.StaticTable`, :mod:`.static_robot`) is chosen once, when the node starts;
:class:`SharedTable` adds what the node records about agents' visits, and never calls back
into the process that owns it. A base that also offers its learnt parameters as a flat vector
(a ``Trainer``: ``params``, ``param_layout``, ``set_params``, ``samples``, ``learner_kind``)
is wrapped in :class:`SharedLearner`, which offers them too (:func:`shared_provider` picks).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any, Protocol

import numpy as np

from dfrl.experiments.robot_host.files import CsvLog, share_row
from dfrl.experiments.robot_host.lines import ProtocolLines
from dfrl.experiments.robot_host.share_notes import ShareNotes
from dfrl.pybridge.providers import ParamsProvider, TableProvider, read_table, write_table

__all__ = ["SharedTable", "SharedLearner", "shared_provider"]


class LiveTable(TableProvider, Protocol):
    """A base whose live table may be looked at without that counting as an agent's read (a
    :class:`dfrl.robots.training.Trainer`, a grid view)."""

    @property
    def q_table(self) -> np.ndarray: ...


class LiveLearner(LiveTable, ParamsProvider, Protocol):
    """A :class:`LiveTable` that offers its parameters too."""


class SharedTable:
    """A :class:`dfrl.pybridge.TableProvider` over ``base`` that records shares.

    Every read of the Q-table by an agent (:meth:`read_table`) writes a ``DFRL_EVENT get``
    line; every applied :meth:`write_table` (already validated by the bridge) counts a share,
    appends a row to the shares file (with the write's origin: round, agent, epoch, and the
    sum it left, :attr:`q_sum`), writes a ``DFRL_EVENT set`` line and calls ``on_share`` (the
    robot's checkpoint). The base is read and written through the same verb pair
    (:func:`dfrl.pybridge.providers.read_table` and ``write_table``). ``q_table`` is a plain
    getter, for the robot's own use; ``set_q_table``, ``set_q_table_from`` and
    ``table_read`` are deprecated names of before the verb pair.

    Parameters
    ----------
    base : LiveTable
        Where the table lives.
    robot : str
    shares_log : CsvLog
        ``shares_<robot>.csv``.
    lines : ProtocolLines
    on_share : callable, optional
        Called after every applied share (no arguments).
    shares : int
        Shares applied before (a resumed run).
    notes : ShareNotes, optional
        Where a write absorbed by distillation (a base with ``last_distillation``, a grid
        view) and a read of the parameters (their samples: the FedAvg weight) are recorded.

    Attributes
    ----------
    iteration : int
        The robot's iteration, set by the control loop (recorded with each event).
    shares : int
        Shares applied so far.
    """

    def __init__(
        self,
        base: LiveTable,
        robot: str,
        shares_log: CsvLog,
        lines: ProtocolLines,
        on_share: Callable[[], None] | None = None,
        shares: int = 0,
        notes: ShareNotes | None = None,
    ) -> None:
        self.base = base
        self.notes = notes
        self.robot = robot
        self.shares_log = shares_log
        self.lines = lines
        self.on_share = on_share
        self.iteration = 0
        self.shares = shares

    @property
    def q_table(self) -> np.ndarray:
        """The base's table, a plain getter (no agent's read is recorded)."""
        return self.base.q_table

    @property
    def q_sum(self) -> float:
        """The sum the robot's metrics call ``q_sum``: its table's (recorded with each share)."""
        return float(self.base.q_table.sum())

    def read_table(self) -> np.ndarray:
        """An agent's read of the Q-table: the base's, the read recorded."""
        table = read_table(self.base)
        self.lines.event("get", self.iteration)
        return table

    @property
    def visits(self) -> np.ndarray:
        return self.base.visits

    def write_table(self, table: np.ndarray, origin: Mapping[str, Any]) -> None:
        """Apply a share written by an agent; ``origin`` holds the options of its write
        (``round``, ``agent``, ``epoch``; see :mod:`dfrl.pybridge.serving`)."""
        write_table(self.base, table, {})
        self.shares += 1
        self.shares_log.row(
            share_row(
                self.robot, self.shares, self.iteration, self.base.q_table, origin, self.q_sum
            ),
            flush=True,
        )
        report = getattr(self.base, "last_distillation", None)
        if report is not None and self.notes is not None:  # this write's (a grid view)
            self.notes.write_distillation(self.iteration, origin, report)
        self.lines.event("set", self.iteration)
        if self.on_share is not None:
            self.on_share()

    def table_read(self) -> None:
        """Deprecated: an agent's read is recorded by :meth:`read_table`."""
        self.lines.event("get", self.iteration)

    def set_q_table(self, table: np.ndarray) -> None:
        """Deprecated name of :meth:`write_table` (no origin)."""
        self.write_table(table, {})

    def set_q_table_from(self, table: np.ndarray, origin: Mapping[str, Any]) -> None:
        """Deprecated name of :meth:`write_table`."""
        self.write_table(table, origin)


class SharedLearner(SharedTable):
    """A :class:`SharedTable` whose base also offers its parameters (a
    :class:`dfrl.pybridge.ParamsProvider`); a parameter write is a share like a table write.

    Its ``read_table``, ``visits`` and ``write_table`` are the base's (a function learner's
    raise: the bridge never asks, it registers such a robot without a table).
    """

    base: LiveLearner

    @property
    def params(self) -> np.ndarray:
        return self.base.params

    @property
    def q_sum(self) -> float:
        """The sum the robot's metrics call ``q_sum``: a function learner's parameters' (a
        grid federation's write too: it is distilled into them), a tabular one's table's."""
        if self.base.learner_kind == "function":
            return float(self.base.params.sum())
        return super().q_sum

    @property
    def param_layout(self) -> Any:
        return self.base.param_layout

    @property
    def samples(self) -> int:
        return self.base.samples

    @property
    def learner_kind(self) -> str:
        return self.base.learner_kind

    def params_read(self) -> None:
        """An agent read the parameters (the bridge calls it after serving the read); their
        samples (the FedAvg weight) are noted."""
        self.lines.event("get", self.iteration)
        if self.notes is not None:
            self.notes.write_weight(self.iteration, self.base.samples)

    def set_params(self, vec: np.ndarray) -> None:
        self.set_params_from(vec, {})

    def set_params_from(self, vec: np.ndarray, origin: Mapping[str, Any]) -> None:
        """Apply a share of parameters written by an agent (already validated by the bridge);
        recorded as a table share is, with the digest of the vector."""
        self.base.set_params(vec)
        self.shares += 1
        self.shares_log.row(
            share_row(
                self.robot, self.shares, self.iteration, self.base.params, origin, self.q_sum
            ),
            flush=True,
        )
        self.lines.event("set", self.iteration)
        if self.on_share is not None:
            self.on_share()


def shared_provider(
    base: Any,
    robot: str,
    shares_log: CsvLog,
    lines: ProtocolLines,
    on_share: Callable[[], None] | None = None,
    shares: int = 0,
    notes: ShareNotes | None = None,
) -> SharedTable:
    """A :class:`SharedLearner` over a base that offers parameters, else a :class:`SharedTable`
    (arguments as :class:`SharedTable`'s)."""
    offers = all(
        name in dir(base)
        for name in ("params", "param_layout", "set_params", "samples", "learner_kind")
    )
    cls = SharedLearner if offers else SharedTable
    return cls(base, robot, shares_log, lines, on_share, shares, notes)
