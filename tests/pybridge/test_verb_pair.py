"""One verb pair along a Q-table's path (issue 37): an agent's ``robot_resources``
``read_robot_table/3`` and ``write_robot_table/3`` reach a provider's ``read_table()`` and
``write_table(table, origin)``; the deprecated Prolog names of before still do."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from bridge_helpers import run_agent

from dfrl.pybridge import Atom, Term, Var


class VerbRobot:
    """A provider with the verb pair only (no ``q_table``, no ``set_q_table``)."""

    def __init__(self) -> None:
        self._q = np.arange(4.0).reshape(2, 2)
        self.reads = 0
        self.writes: list[tuple[np.ndarray, dict[str, Any]]] = []

    def read_table(self) -> np.ndarray:
        self.reads += 1
        return self._q.copy()

    @property
    def visits(self) -> np.ndarray:
        return np.ones((2, 2), dtype=np.int64)

    def write_table(self, table: np.ndarray, origin: Mapping[str, Any]) -> None:
        self._q = np.array(table)
        self.writes.append((np.array(table), dict(origin)))


def _call(node: Any, name: str, *args: Any) -> Any:
    return run_agent(node, Term(":", Atom("robot_resources"), Term(name, *args)))


def test_the_verb_pair_reaches_the_provider(node) -> None:
    robot = VerbRobot()
    node.register_robot("r1", robot, shape=(2, 2))
    got = _call(node, "read_robot_table", Atom("r1"), Var("T"), [])
    assert got.name == "true", got
    table = got.args[0].args[1].args[1]  # true(robot_resources:Goal)
    assert table == Term("qtable", [2, 2], [0.0, 1.0, 2.0, 3.0]) and robot.reads == 1
    new = Term("qtable", [2, 2], [4.0, 3.0, 2.0, 1.0])
    assert (
        _call(
            node, "write_robot_table", Atom("r1"), new, [Term("round", 7), Term("agent", Atom("a"))]
        ).name
        == "true"
    )
    assert len(robot.writes) == 1
    written, origin = robot.writes[0]
    assert np.array_equal(written, [[4.0, 3.0], [2.0, 1.0]])
    assert origin == {"round": 7, "agent": "a"}
    # the deprecated names of before are the same operations
    old = Term("qtable", [2, 2], [1.0, 1.0, 1.0, 1.0])
    assert _call(node, "set_robot_table", Atom("r1"), old, []).name == "true"
    assert np.array_equal(robot.writes[-1][0], np.ones((2, 2)))
    again = _call(node, "get_robot_table", Atom("r1"), Var("T"), [])
    assert again.args[0].args[1].args[1] == Term("qtable", [2, 2], [1.0, 1.0, 1.0, 1.0])
    assert robot.reads == 2
