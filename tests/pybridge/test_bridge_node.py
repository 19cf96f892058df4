"""Bridge and robot_bridge.pl together: agents in Prolog threads, the test's main thread
serving their requests like a control loop."""

from __future__ import annotations

import time

import numpy as np
import pytest
from bridge_helpers import HELPER, ArrayRobot, agent_result, run_agent, spawn

from dfrl.pybridge import Atom, BridgeError, Codec, NodeStateError, PrologError, Bridge, Term, Var


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).view(np.int64)


def _table(result: Term) -> tuple[list[int], np.ndarray]:
    assert isinstance(result, Term) and result.name == "true", result
    goal = result.args[0]
    qtable = goal.args[1]
    assert qtable.name == "qtable"
    shape, values = qtable.args
    return shape, np.array(values, dtype=np.float64)


def _error_formal(result: Term):
    assert isinstance(result, Term) and result.name == "error", result
    err = result.args[0]
    assert err.name == "error", err
    return err.args[0]


def test_self_test_selects_fts(node) -> None:
    assert node.self_test_report.fts_ok and node.self_test_report.text_ok
    assert node.codec is Codec.FTS
    assert node.call("bridge_codec", Var("C"), module="robot_bridge") == {"C": Atom("fts")}


def test_register_and_list_robots(node) -> None:
    node.register_robot("r1", ArrayRobot(3, 2), algo="sarsa")
    node.register_robot(7, ArrayRobot(2, 2))
    robots = dict(node.robots())
    assert robots[Atom("r1")] == [
        Term("algo", Atom("sarsa")),
        Term("shape", [3, 2]),
        Term("learner", Atom("tabular")),
    ]
    assert robots[7][1] == Term("shape", [2, 2])
    node.unregister_robot(7)
    assert [r for r, _ in node.robots()] == [Atom("r1")]


def test_register_robot_algorithm_keyword_is_deprecated(node) -> None:
    with pytest.warns(DeprecationWarning, match=r"algorithm=\.\.\.\) is deprecated; use algo"):
        node.register_robot("r1", ArrayRobot(2, 2), algorithm="sarsa")
    assert dict(node.robots())[Atom("r1")][0] == Term("algo", Atom("sarsa"))
    with pytest.raises(TypeError, match="give algo only"):
        node.register_robot("r2", ArrayRobot(2, 2), algo="sarsa", algorithm="sarsa")


@pytest.mark.parametrize("codec", ["fts", "text"])
def test_get_qtable_bit_exact_from_prolog_thread(node, codec) -> None:
    node.codec = codec
    robot = ArrayRobot(500, 8, seed=3)
    q = robot.q_table
    q[0, :4] = [-0.0, 5e-324, 1.7976931348623157e308, 0.1]
    robot.set_q_table(q)
    node.register_robot("r1", robot)
    shape, values = _table(run_agent(node, Term("get_qtable", Atom("r1"), Var())))
    assert shape == [500, 8]
    assert np.array_equal(_bits(values), _bits(robot.q_table.reshape(-1)))


@pytest.mark.parametrize("codec", ["fts", "text"])
def test_python_prolog_python_round_trip(node, codec) -> None:
    """get then set the same table from an agent: the robot's table is unchanged bit for bit
    (random bit patterns: every exponent, subnormals, -0.0), and a table made in Prolog
    arrives exactly."""
    node.codec = codec
    robot = ArrayRobot(64, 4, seed=5)
    rng = np.random.default_rng(11)
    bits = rng.integers(-(2**63), 2**63 - 1, (64, 4), dtype=np.int64)
    awkward = bits.view(np.float64).copy()
    awkward[~np.isfinite(awkward)] = -0.0
    awkward[0, :3] = [5e-324, -0.0, 1.7976931348623157e308]
    robot.set_q_table(awkward)
    robot.sets = 0
    node.register_robot("r1", robot)
    before = robot.q_table
    goal = Term(
        ",", Term("get_qtable", Atom("r1"), Var("T")), Term("set_qtable", Atom("r1"), Var("T"))
    )
    assert run_agent(node, goal).name == "true"
    assert robot.sets == 1
    assert np.array_equal(_bits(robot.q_table), _bits(before))
    # a table built by the agent: each value halved in Prolog arithmetic
    half = Term(">>", [Var("X"), Var("Y")], Term("is", Var("Y"), Term("/", Var("X"), 2)))
    halve = Term(
        ",",
        Term("get_qtable", Atom("r1"), Term("qtable", Var("S"), Var("V"))),
        Term(
            ",",
            Term("maplist", half, Var("V"), Var("W")),
            Term("set_qtable", Atom("r1"), Term("qtable", Var("S"), Var("W"))),
        ),
    )
    assert run_agent(node, halve).name == "true"
    assert np.array_equal(_bits(robot.q_table), _bits(before / 2))


def test_get_visits_as_floats(node) -> None:
    robot = ArrayRobot(10, 3)
    node.register_robot("r1", robot)
    shape, values = _table(run_agent(node, Term("get_visits", Atom("r1"), Var())))
    assert shape == [10, 3]
    assert np.array_equal(values, robot.visits.reshape(-1).astype(np.float64))


def test_qtable_and_visits_together(node) -> None:
    robot = ArrayRobot(7, 3)
    node.register_robot("r1", robot)
    result = run_agent(node, Term("get_qtable_and_visits", Atom("r1"), Var(), Var()))
    assert result.name == "true", result
    _, table, visits = result.args[0].args
    assert table.args[0] == [7, 3] and visits.args[0] == [7, 3]
    assert np.array_equal(_bits(np.array(table.args[1])), _bits(robot.q_table.reshape(-1)))
    assert np.array_equal(np.array(visits.args[1]), robot.visits.reshape(-1).astype(np.float64))
    formal = _error_formal(run_agent(node, Term("get_qtable_and_visits", Atom("zz"), Var(), Var())))
    assert formal == Term("existence_error", Atom("robot"), Atom("zz"))


def test_set_accepts_integers(node) -> None:
    robot = ArrayRobot(2, 2)
    node.register_robot("r1", robot)
    table = Term("qtable", [2, 2], [1, 2.5, 3, -4])
    assert run_agent(node, Term("set_qtable", Atom("r1"), table)).name == "true"
    assert np.array_equal(robot.q_table, np.array([[1.0, 2.5], [3.0, -4.0]]))


def test_unknown_robot_is_existence_error(node) -> None:
    node.register_robot("r1", ArrayRobot(2, 2))
    for goal in (
        Term("get_qtable", Atom("nobody"), Var()),
        Term("get_visits", Atom("nobody"), Var()),
        Term("set_qtable", Atom("nobody"), Term("qtable", [2, 2], [0.0] * 4)),
    ):
        formal = _error_formal(run_agent(node, goal))
        assert formal == Term("existence_error", Atom("robot"), Atom("nobody"))


def test_robot_unregistered_while_request_queued(node) -> None:
    """The Python side checks too: a request for a robot forgotten in the meantime."""
    node.register_robot("r1", ArrayRobot(2, 2))
    spawn(node, "late_agent", Term("get_qtable", Atom("r1"), Var()))
    queued = Term("size", 1)
    deadline = time.monotonic() + 5
    while node.call("message_queue_property", Atom("robot_bridge_requests"), queued) is None:
        assert time.monotonic() < deadline
        time.sleep(0.001)
    node._robots.clear()  # as if the Python side had lost the robot
    result = agent_result(node, "late_agent", serve=True)
    assert _error_formal(result) == Term("existence_error", Atom("robot"), Atom("r1"))


_NAN = float("nan")


@pytest.mark.parametrize(
    "table, expected",
    [
        (
            Term("qtable", [2, 3], [0.0] * 6),  # wrong shape
            Term("domain_error", Term("shape", [2, 2]), [2, 3]),
        ),
        (
            Term("qtable", [2, 2], [0.0] * 3),  # wrong number of values
            Term("domain_error", Term("qtable_size", 4), 3),
        ),
        (Term("qtable", [2, 2], [0.0] * 5), Term("domain_error", Term("qtable_size", 4), 5)),
        (
            Term("qtable", [2, 2], [0.0, 1.0, Atom("x"), 2.0]),  # not a number
            Term("type_error", Atom("number"), Atom("x")),
        ),
        (
            Term("qtable", [2, 2], [0.0, float("inf"), 1.0, 2.0]),  # non-finite
            Term("domain_error", Atom("finite_float"), float("inf")),
        ),
        (
            Term("qtable", [2, 2], [0.0, 1.0, 2.0, -float("inf")]),
            Term("domain_error", Atom("finite_float"), -float("inf")),
        ),
        (Term("qtable", [2, 2], [0.0, _NAN, 1.0, 2.0]), None),  # NaN: checked below
        (
            Term("table", [2, 2], [0.0] * 4),  # not a qtable term
            Term("type_error", Atom("qtable"), Term("table", [2, 2], [0.0] * 4)),
        ),
    ],
)
@pytest.mark.parametrize("codec", ["fts", "text"])
def test_bad_set_is_an_error_and_table_unchanged(node, table, expected, codec) -> None:
    """Validated once, where the table enters Python; the message names what is wrong."""
    node.codec = codec
    robot = ArrayRobot(2, 2)
    node.register_robot("r1", robot, shape=(2, 2))
    before = robot.q_table
    formal = _error_formal(run_agent(node, Term("set_qtable", Atom("r1"), table)))
    if expected is None:
        assert formal.name == "domain_error" and formal.args[0] == Atom("finite_float"), formal
        assert np.isnan(formal.args[1])
    else:
        assert formal == expected
    assert np.array_equal(_bits(robot.q_table), _bits(before))
    assert robot.sets == 0


def test_validation_happens_in_python_only(node) -> None:
    """The Prolog side sends a wrong table as it is; the host refuses it without calling
    the provider."""
    robot = ArrayRobot(2, 2)
    node.register_robot("r1", robot, shape=(2, 2))
    spawn(node, "bad_writer", Term("set_qtable", Atom("r1"), Term("qtable", [4, 1], [0.0] * 4)))
    deadline = time.monotonic() + 5
    request = None
    while request is None:
        assert time.monotonic() < deadline
        sol = node.call("bridge_next_request", Var("R"), 0.05, module="robot_bridge")
        request = sol and sol["R"]
    req_id, op = request.args
    assert op.name == "write_table" and op.args[1] == [4, 1]
    from dfrl.pybridge.serving import RequestError, validate_write

    with pytest.raises(RequestError) as info:
        validate_write((2, 2), op.args[1], op.args[2])
    node.call("bridge_reply", req_id, Term("error", info.value.formal), module="robot_bridge")
    assert _error_formal(agent_result(node, "bad_writer")) == Term(
        "domain_error", Term("shape", [2, 2]), [4, 1]
    )
    assert robot.sets == 0


def test_shape_is_given_at_registration(node) -> None:
    class Unreadable(ArrayRobot):
        @property
        def q_table(self) -> np.ndarray:
            raise AssertionError("registration must not read the table")

    node.register_robot("r1", Unreadable(3, 2), shape=(3, 2))
    assert dict(node.robots())[Atom("r1")][1] == Term("shape", [3, 2])
    for bad in ((3,), (0, 2), (3, 2.5)):
        with pytest.raises(ValueError):
            node.register_robot("r2", ArrayRobot(3, 2), shape=bad)


def test_python_failure_becomes_python_error(node) -> None:
    class Broken(ArrayRobot):
        broken = False

        @property
        def q_table(self) -> np.ndarray:
            if self.broken:
                raise RuntimeError("sensor down")
            return super().q_table

    robot = Broken(2, 2)
    node.register_robot("r1", robot)
    robot.broken = True
    formal = _error_formal(run_agent(node, Term("get_qtable", Atom("r1"), Var())))
    assert formal == Term("python_error", Atom("RuntimeError"), "sensor down")


def test_python_failure_in_set_becomes_python_error(node) -> None:
    class Refusing(ArrayRobot):
        def set_q_table(self, table: np.ndarray) -> None:
            raise ValueError("learning in progress")

    node.register_robot("r1", Refusing(2, 2))
    goal = Term("set_qtable", Atom("r1"), Term("qtable", [2, 2], [0.0] * 4))
    formal = _error_formal(run_agent(node, goal))
    assert formal == Term("python_error", Atom("ValueError"), "learning in progress")


def test_timeout_when_nobody_serves(node) -> None:
    node.register_robot("r1", ArrayRobot(2, 2))
    goal = Term("get_qtable", Atom("r1"), Var(), [Term("timeout", 0.2)])
    result = run_agent(node, goal, serve=False)
    assert _error_formal(result) == Term("timeout_error", Atom("bridge"), Atom("r1"))
    # the expired request is dropped, not served later
    assert node.serve_pending() == 0
    # the default timeout comes from the flag
    node.request_timeout = 0.1
    assert node.request_timeout == pytest.approx(0.1)
    result = run_agent(
        node, Term("set_qtable", Atom("r1"), Term("qtable", [2, 2], [0.0] * 4)), serve=False
    )
    assert _error_formal(result) == Term("timeout_error", Atom("bridge"), Atom("r1"))


def test_waiting_from_the_serving_thread_is_refused(node) -> None:
    node.register_robot("r1", ArrayRobot(2, 2))
    with pytest.raises(PrologError) as info:
        node.call("get_qtable", Atom("r1"), Var("T"))
    assert info.value.formal.name == "permission_error"


def test_prolog_errors_arrive_as_terms(node) -> None:
    with pytest.raises(PrologError) as info:
        node.call(
            "bridge_register_robot", Atom("r1"), [Term("shape", [0, 2])], module="robot_bridge"
        )
    domain = Term("shape", [Atom("nstates"), Atom("nactions")])
    assert info.value.formal == Term("domain_error", domain, [0, 2])


def test_serve_pending_respects_max(node) -> None:
    node.register_robot("r1", ArrayRobot(2, 2))
    for i in range(3):
        spawn(node, f"many_{i}", Term("get_qtable", Atom("r1"), Var()))
    served, deadline = 0, time.monotonic() + 5
    while served < 3 and time.monotonic() < deadline:
        n = node.serve_pending(max_requests=1)
        assert n <= 1
        served += n
    assert served == 3
    for i in range(3):
        assert agent_result(node, f"many_{i}").name == "true"


def test_one_node_at_a_time_and_close(node) -> None:
    with pytest.raises(NodeStateError):
        Bridge()
    node.register_robot("r1", ArrayRobot(2, 2))
    spawn(node, "stuck_agent", Term("get_qtable", Atom("r1"), Var()))
    assert node.close() == []
    assert node.closed
    with pytest.raises(NodeStateError):
        node.serve_pending()
    again = Bridge()
    again.close()


def test_any_float_layout_is_served_row_major(node) -> None:
    class Fortran(ArrayRobot):
        @property
        def q_table(self) -> np.ndarray:
            return np.asfortranarray(super().q_table.astype(np.float32))

    robot = Fortran(6, 3)
    node.register_robot("r1", robot, shape=(6, 3))
    shape, values = _table(run_agent(node, Term("get_qtable", Atom("r1"), Var())))
    assert shape == [6, 3]
    assert np.array_equal(values, robot.q_table.astype(np.float64).reshape(-1))


def test_non_floats_that_look_like_floats_are_converted_or_refused(node) -> None:
    """[1, 10**23] serialises to exactly the length of two floats, so the agent side sends it
    as is; the host's tag check refuses it and the agent converts and asks again."""
    robot = ArrayRobot(2, 2)
    node.register_robot("r1", robot)
    goal = Term("set_qtable", Atom("r1"), Term("qtable", [2, 2], [1, 10**23, 2.0, 3.0]))
    assert run_agent(node, goal).name == "true"
    assert np.array_equal(robot.q_table, np.array([[1.0, 1e23], [2.0, 3.0]]))
    assert robot.sets == 1
    goal = Term("set_qtable", Atom("r1"), Term("qtable", [2, 2], [Atom("a"), 10**23, 2.0, 3.0]))
    assert _error_formal(run_agent(node, goal)) == Term("type_error", Atom("number"), Atom("a"))
    assert robot.sets == 1


def test_fts_self_test_failure_falls_back_to_text(monkeypatch) -> None:
    """An encoder that disagrees with this Prolog (here: a wrong size field) must be caught
    before Prolog ever deserialises its bytes; the node then uses the text codec."""
    from dfrl.pybridge import codec as codec_module

    real = codec_module.encode_fts

    def skewed(values):
        data = bytearray(real(values))
        if len(data) > 2:
            data[1] ^= 0x01
        return data

    monkeypatch.setattr(codec_module, "encode_fts", skewed)
    n = Bridge()
    try:
        assert not n.self_test_report.fts_ok and n.self_test_report.text_ok
        assert n.codec is Codec.TEXT
        with pytest.raises(BridgeError):
            n.codec = "fts"
        robot = ArrayRobot(3, 3)
        n.register_robot("r1", robot)
        n.call("use_module", Atom(str(HELPER)))
        shape, values = _table(run_agent(n, Term("get_qtable", Atom("r1"), Var())))
        assert np.array_equal(_bits(values), _bits(robot.q_table.reshape(-1)))
    finally:
        n.close()


def test_concurrent_agents_see_whole_tables_only(node) -> None:
    """Four agents each write a table filled with their own number and read it back, many
    times, while the main thread serves: every read is one whole table (never torn)."""
    robot = ArrayRobot(100, 4)
    node.register_robot("r1", robot)
    for k in range(4):
        spawn(node, f"stress_{k}", Term("stress", Atom("r1"), k, 15, Var()))
    results = [agent_result(node, f"stress_{k}", timeout=20, serve=True) for k in range(4)]
    for k, result in enumerate(results):
        assert result.name == "true", result
        assert result.args[0].args[3] == 0, f"agent {k} saw a torn table"
    q = robot.q_table
    assert np.all(q == q.flat[0]) and q.flat[0] in {0.0, 1.0, 2.0, 3.0}
    assert robot.sets == 60
