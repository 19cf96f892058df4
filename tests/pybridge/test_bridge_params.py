"""Parameter vectors through the bridge (issue 19): a provider without a robot
(:class:`StaticParams`), what a robot offers in its props, and every write validated once at
the boundary (``serving.validate_params``), seen from an agent thread."""

from __future__ import annotations

import math

import numpy as np
import pytest
from bridge_helpers import ArrayRobot, run_agent

from dfrl.pybridge import Atom, StaticParams, Term, Var
from dfrl.pybridge.providers import check_layout, layout_size

LAYOUT = [("w1", (2, 3)), ("b1", (3,)), ("w2", (3, 1))]  # 6 + 3 + 3 = 12 floats
LAYOUT_TERM = [
    Term("-", Atom("w1"), [2, 3]),
    Term("-", Atom("b1"), [3]),
    Term("-", Atom("w2"), [3, 1]),
]
RR = "robot_resources"


def _get(robot: str) -> Term:
    return Term(":", Atom(RR), Term("get_robot_params", Atom(robot), Var("P"), []))


def _set(robot: str, layout: list, values: list) -> Term:
    return Term(
        ":", Atom(RR), Term("set_robot_params", Atom(robot), Term("params", layout, values), [])
    )


def _formal(result: Term) -> Term:
    assert result.name == "error", result
    return result.args[0].args[0]


# -- the provider (pure) ----------------------------------------------------------------------
def test_static_params_is_a_real_provider() -> None:
    p = StaticParams(LAYOUT, seed=3, samples=40)
    assert layout_size(p.param_layout) == 12 and p.params.shape == (12,)
    assert p.samples == 40 and p.learner_kind == "function"
    assert np.array_equal(p.params, StaticParams(LAYOUT, seed=3).params)  # same seed
    p.params[0] = 99.0  # a getter hands out a copy
    assert p.params[0] != 99.0
    p.set_params(np.arange(12.0))
    assert np.array_equal(p.params, np.arange(12.0)) and p.sets == 1
    for bad in (np.arange(11.0), np.full(12, np.nan)):
        with pytest.raises(ValueError):
            p.set_params(bad)
    assert p.sets == 1


@pytest.mark.parametrize(
    "bad",
    [
        [],
        [("w", (0,))],
        [("w", (2,)), ("w", (1,))],
        [("", (1,))],
        [("w", (-1,))],
        [("w", 3)],
        ["w"],
    ],
)
def test_bad_layouts_are_refused(bad) -> None:
    with pytest.raises(ValueError):
        check_layout(bad)


# -- through the bridge -----------------------------------------------------------------------
def test_function_learner_offers_params_only(node) -> None:
    node.register_robot("f1", StaticParams(LAYOUT, seed=1, samples=5), algo="dqn")
    ((_, props),) = [rp for rp in node.robots() if rp[0] == Atom("f1")]
    assert props == [
        Term("algo", Atom("dqn")),
        Term("learner", Atom("function")),
        Term("layout", LAYOUT_TERM),
    ]
    table = run_agent(node, Term(":", Atom(RR), Term("get_robot_table", Atom("f1"), Var(), [])))
    assert _formal(table) == Term("existence_error", Atom("qtable"), Atom("f1"))


def test_tabular_robot_says_so(node) -> None:
    node.register_robot("r1", ArrayRobot(4, 2), shape=(4, 2))
    ((_, props),) = node.robots()
    assert props == [
        Term("algo", Atom("qlearning")),
        Term("shape", [4, 2]),
        Term("learner", Atom("tabular")),
    ]
    got = run_agent(node, _get("r1"))
    assert _formal(got) == Term("existence_error", Atom("params"), Atom("r1"))


def test_registration_checks_what_is_offered(node) -> None:
    with pytest.raises(TypeError):
        node.register_robot("f1", StaticParams(LAYOUT), learner="tabular")  # no q_table
    with pytest.raises(ValueError):
        node.register_robot("f1", StaticParams(LAYOUT), shape=(3, 4))
    with pytest.raises(TypeError):
        node.register_robot("r1", ArrayRobot(2, 2), learner="function")  # no params
    with pytest.raises(ValueError):
        node.register_robot("r1", ArrayRobot(2, 2), learner="neural")


@pytest.mark.parametrize("codec", ["fts", "text"])
def test_read_and_write_params_bit_exact(node, codec) -> None:
    node.codec = codec
    robot = StaticParams(LAYOUT, seed=7, samples=123)
    node.register_robot("f1", robot)
    got = run_agent(node, _get("f1"))
    assert got.name == "true", got
    params = got.args[0].args[1].args[1]
    assert params.name == "params"
    layout, samples, values = params.args
    assert layout == LAYOUT_TERM and samples == 123
    assert np.array_equal(np.array(values), robot.params)
    new = [-0.0, 5e-324, 1.0, 2, -3.5, 1e308, 0.1, 0.2, 0.3, 4.0, 5.0, 6.0]  # an int too
    done = run_agent(node, _set("f1", LAYOUT_TERM, new))
    assert done.name == "true", done
    assert robot.sets == 1
    assert robot.params.tobytes() == np.array(new, dtype=np.float64).tobytes()


def test_write_of_wrong_length(node) -> None:
    robot = StaticParams(LAYOUT, seed=2)
    node.register_robot("f1", robot)
    before = robot.params
    for n in (11, 13):
        bad = run_agent(node, _set("f1", LAYOUT_TERM, [1.0] * n))
        assert _formal(bad) == Term("domain_error", Term("params_size", 12), n)
    assert robot.sets == 0 and np.array_equal(robot.params, before)


@pytest.mark.parametrize("codec", ["fts", "text"])
@pytest.mark.parametrize("value", [math.inf, -math.inf, math.nan])
def test_write_of_non_finite(node, codec, value) -> None:
    node.codec = codec
    robot = StaticParams(LAYOUT, seed=2)
    node.register_robot("f1", robot)
    bad = run_agent(node, _set("f1", LAYOUT_TERM, [1.0] * 5 + [value] + [1.0] * 6))
    formal = _formal(bad)
    assert formal.name == "domain_error" and formal.args[0] == Atom("finite_float")
    assert robot.sets == 0


def test_write_of_another_layout(node) -> None:
    robot = StaticParams(LAYOUT, seed=2)
    node.register_robot("f1", robot)
    other = [Term("-", Atom("w1"), [3, 2])] + LAYOUT_TERM[1:]  # same size, transposed
    bad = run_agent(node, _set("f1", other, [1.0] * 12))
    assert _formal(bad) == Term("domain_error", Term("param_layout", LAYOUT_TERM), other)
    assert robot.sets == 0


def test_unknown_robot(node) -> None:
    node.register_robot("f1", StaticParams(LAYOUT))
    for goal in (_get("nobody"), _set("nobody", LAYOUT_TERM, [1.0] * 12)):
        assert _formal(run_agent(node, goal)) == Term(
            "existence_error", Atom("robot"), Atom("nobody")
        )


def test_robot_gone_while_queued_is_unknown_at_the_host(node) -> None:
    """The Prolog side knew the robot; the host forgot it before serving: the host's check."""
    node.register_robot("f1", StaticParams(LAYOUT))
    node._robots.pop(Atom("f1"))  # as if unregistered in Python only
    got = run_agent(node, _get("f1"))
    assert _formal(got) == Term("existence_error", Atom("robot"), Atom("f1"))


def test_write_origin_and_read_notice(node) -> None:
    class Recording(StaticParams):
        def __init__(self) -> None:
            super().__init__(LAYOUT, seed=4, samples=2)
            self.origins: list[dict] = []
            self.reads = 0

        def set_params_from(self, vec: np.ndarray, origin: dict) -> None:
            self.origins.append(origin)
            self.set_params(vec)

        def params_read(self) -> None:
            self.reads += 1

    robot = Recording()
    node.register_robot("f1", robot)
    assert run_agent(node, _get("f1")).name == "true"
    goal = Term(
        ":",
        Atom(RR),
        Term(
            "set_robot_params",
            Atom("f1"),
            Term("params", LAYOUT_TERM, [0.5] * 12),
            [Term("round", 3), Term("agent", Atom("fed_dqn"))],
        ),
    )
    assert run_agent(node, goal).name == "true"
    assert robot.reads == 1 and robot.origins == [{"round": 3, "agent": "fed_dqn"}]


def test_params_bench_smoke() -> None:
    from dfrl.pybridge.params_bench import bench

    (row,) = bench([8], repeats=2, warmup=0)
    assert row["floats"] == 8 and row["params"]["pairs"] == 2 and row["table"]["pairs"] == 2
    assert row["params"]["bit_exact"] and row["params"]["pair"]["median_ms"] > 0
