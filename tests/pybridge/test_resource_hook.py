"""An agent reaches the robots of this process through the platform's resource hook
(platform_pl/robot_resources.pl), which the bridge implements; nothing goes through ``user``."""

from __future__ import annotations

import numpy as np
from bridge_helpers import ArrayRobot, run_agent

from dfrl.pybridge import Atom, Term, Var


def _half(x: str, y: str) -> Term:
    return Term(">>", [Var(x), Var(y)], Term("is", Var(y), Term("/", Var(x), 2)))


def test_agent_reads_and_writes_through_robot_resources(node) -> None:
    robot = ArrayRobot(81, 3, seed=9)
    node.register_robot("r1", robot, shape=(81, 3), algo="sarsa")
    before = robot.q_table
    opts = [Term("timeout", 5.0)]
    rr = "robot_resources"
    goal = Term(
        ",",
        Term(":", Atom(rr), Term("hosted_robot", Atom("r1"), Var("Props"))),
        Term(
            ",",
            Term(
                ":",
                Atom(rr),
                Term("get_robot_table", Atom("r1"), Term("qtable", Var("S"), Var("V")), opts),
            ),
            Term(
                ",",
                Term("maplist", _half("X", "Y"), Var("V"), Var("W")),
                Term(
                    ":",
                    Atom(rr),
                    Term("set_robot_table", Atom("r1"), Term("qtable", Var("S"), Var("W")), opts),
                ),
            ),
        ),
    )
    result = run_agent(node, goal)
    assert result.name == "true", result
    props = result.args[0][0].args[1].args[1]  # the conjunction comes back as a tuple
    assert props == [
        Term("algo", Atom("sarsa")),
        Term("shape", [81, 3]),
        Term("learner", Atom("tabular")),
    ]
    assert robot.sets == 1
    assert np.array_equal(robot.q_table, before / 2)


def test_tables_and_errors_through_robot_resources(node) -> None:
    robot = ArrayRobot(4, 2)
    node.register_robot("r1", robot, shape=(4, 2))
    got = run_agent(
        node,
        Term(
            ":",
            Atom("robot_resources"),
            Term("get_robot_tables", Atom("r1"), Var("T"), Var("V"), []),
        ),
    )
    assert got.name == "true", got
    _, table, visits, _ = got.args[0].args[1].args
    assert np.array_equal(np.array(table.args[1]), robot.q_table.reshape(-1))
    assert np.array_equal(np.array(visits.args[1]), robot.visits.reshape(-1).astype(float))
    # unknown robot: the hook module's existence error; a bad write: the host's error
    missing = run_agent(
        node, Term(":", Atom("robot_resources"), Term("get_robot_table", Atom("nobody"), Var(), []))
    )
    assert missing.args[0].args[0] == Term("existence_error", Atom("robot"), Atom("nobody"))
    bad = run_agent(
        node,
        Term(
            ":",
            Atom("robot_resources"),
            Term("set_robot_table", Atom("r1"), Term("qtable", [4, 2], [1.0] * 7), []),
        ),
    )
    assert bad.args[0].args[0] == Term("domain_error", Term("qtable_size", 8), 7)
    assert robot.sets == 0


def test_packed_values_cross_the_hook_bit_exact(node) -> None:
    # values(packed): the table comes packed (fts(String), float_vectors.pl) and a packed table
    # is written as it is; r2 then holds r1's table bit for bit
    r1, r2 = ArrayRobot(50, 4, seed=3), ArrayRobot(50, 4, seed=4)
    node.register_robot("r1", r1, shape=(50, 4))
    node.register_robot("r2", r2, shape=(50, 4))
    rr = "robot_resources"
    opts = [Term("values", Atom("packed")), Term("timeout", 5.0)]
    goal = Term(
        ",",
        Term(
            ":",
            Atom(rr),
            Term("get_robot_table", Atom("r1"), Term("qtable", Var("S"), Var("V")), opts),
        ),
        Term(
            ":",
            Atom(rr),
            Term("set_robot_table", Atom("r2"), Term("qtable", Var("S"), Var("V")), []),
        ),
    )
    result = run_agent(node, goal)
    assert result.name == "true", result
    table = result.args[0][0].args[1].args[1]
    assert table.name == "qtable", table
    packed = table.args[1]
    assert isinstance(packed, Term) and packed.name == "fts", packed
    assert r2.sets == 1
    assert r2.q_table.tobytes() == r1.q_table.tobytes()
    # control: without the option the values are a list
    plain = run_agent(node, Term(":", Atom(rr), Term("get_robot_table", Atom("r1"), Var("T"), [])))
    listed = plain.args[0].args[1].args[1]
    assert listed.name == "qtable" and isinstance(listed.args[1], list), listed
    assert np.array_equal(np.array(listed.args[1]), r1.q_table.reshape(-1))


def test_malformed_packed_write_is_refused(node) -> None:
    robot = ArrayRobot(4, 2)
    node.register_robot("r1", robot, shape=(4, 2))
    before = robot.q_table.copy()
    bad = run_agent(
        node,
        Term(
            ":",
            Atom("robot_resources"),
            Term(
                "set_robot_table",
                Atom("r1"),
                Term("qtable", [4, 2], Term("fts", "r\x05garbage\t")),
                [],
            ),
        ),
    )
    assert bad.name != "true", bad
    assert bad.args[0].args[0].name == "domain_error", bad
    assert bad.args[0].args[0].args[0] == Atom("fts_float_list"), bad
    assert robot.sets == 0
    assert np.array_equal(robot.q_table, before)
