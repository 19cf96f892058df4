"""The provider the robot node registers with the bridge: its table, with share bookkeeping.

The table itself (a :class:`dfrl.robots.training.Trainer`, or a
:class:`dfrl.pybridge.StaticTable` in benchmark mode) is chosen once, when the node starts;
:class:`NodeTable` adds what the node records about agents' visits, and never calls back
into the process that owns it.
"""
from __future__ import annotations

import numpy as np

from dfrl.experiments.robot_node.files import CsvLog, share_row
from dfrl.experiments.robot_node.lines import ProtocolLines
from dfrl.pybridge.providers import TableProvider

__all__ = ["NodeTable"]


class NodeTable:
    """A :class:`dfrl.pybridge.TableProvider` over ``base`` that records shares.

    Every read of the Q-table writes a ``DFRL_EVENT get`` line; every applied
    ``set_q_table`` (already validated by the bridge) counts a share, appends a row to the
    shares file and writes a ``DFRL_EVENT set`` line.

    Parameters
    ----------
    base : TableProvider
        Where the table lives.
    robot : str
    shares_log : CsvLog
        ``shares_<robot>.csv``.
    lines : ProtocolLines

    Attributes
    ----------
    iteration : int
        The robot's iteration, set by the control loop (recorded with each event).
    shares : int
        Shares applied so far.
    """

    def __init__(self, base: TableProvider, robot: str, shares_log: CsvLog,
                 lines: ProtocolLines) -> None:
        self.base = base
        self.robot = robot
        self.shares_log = shares_log
        self.lines = lines
        self.iteration = 0
        self.shares = 0

    @property
    def q_table(self) -> np.ndarray:
        self.lines.event("get", self.iteration)
        return self.base.q_table

    @property
    def visits(self) -> np.ndarray:
        return self.base.visits

    def set_q_table(self, table: np.ndarray) -> None:
        self.base.set_q_table(table)
        self.shares += 1
        self.shares_log.row(share_row(self.robot, self.shares, self.iteration, self.base.q_table),
                            flush=True)
        self.lines.event("set", self.iteration)
