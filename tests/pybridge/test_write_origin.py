"""A table write's origin (contract K4): the agent's round, agent and epoch options reach a
provider that defines ``set_q_table_from``; other providers get ``set_q_table`` as before."""

from __future__ import annotations

from typing import Any

import numpy as np
from bridge_helpers import ArrayRobot, run_agent

from dfrl.pybridge import Atom, Term
from dfrl.pybridge.serving import write_origin


class OriginRobot(ArrayRobot):
    def __init__(self) -> None:
        super().__init__(2, 2)
        self.origins: list[dict[str, Any]] = []

    def set_q_table_from(self, table: np.ndarray, origin: dict[str, Any]) -> None:
        self.set_q_table(table)
        self.origins.append(origin)


def _write(node: Any, options: list[Any]) -> Any:
    table = Term("qtable", [2, 2], [1.0, 2.0, 3.0, 4.0])
    return run_agent(
        node,
        Term(":", Atom("robot_resources"), Term("set_robot_table", Atom("r1"), table, options)),
    )


def test_origin_reaches_the_provider(node) -> None:
    robot = OriginRobot()
    node.register_robot("r1", robot, shape=(2, 2))
    opts = [
        Term("timeout", 5),
        Term("round", 3),
        Term("agent", Atom("dfrl_q")),
        Term("epoch", 2),
        Term("note", Term("f", 1)),
    ]
    assert _write(node, opts).name == "true"
    assert _write(node, []).name == "true"
    assert robot.origins == [{"round": 3, "agent": "dfrl_q", "epoch": 2}, {}]
    assert np.array_equal(robot.q_table, [[1.0, 2.0], [3.0, 4.0]])


def test_providers_without_origin_still_get_the_table(node) -> None:
    robot = ArrayRobot(2, 2)
    node.register_robot("r1", robot, shape=(2, 2))
    assert _write(node, [Term("round", 1)]).name == "true"
    assert robot.sets == 1


def test_write_origin_converts_options() -> None:
    assert write_origin([Term("round", 4), Term("agent", Atom("a")), Term("x", 1, 2), 7]) == {
        "round": 4,
        "agent": "a",
    }
    assert write_origin(Atom("[]")) == {}
