"""In-process federation: aggregation maths by hand, determinism with seeds."""

import numpy as np
import pytest

from dfrl.experiments.science.studies.fedsim import AGGREGATIONS, federate
from dfrl.robots.training import TrainerConfig
from dfrl.experiments.processes import find_swipl

# the same three tables as the Prolog check of platform_pl/dfrl_agent/examples/max_visited.pl
Q = [
    np.array([[1.0, -2.0], [0.0, 5.0]]),
    np.array([[0.0, -1.0], [2.0, 7.0]]),
    np.array([[0.5, -3.0], [4.0, 0.0]]),
]
W = [np.array([[3, 4], [0, 1]]), np.array([[0, 2], [0, 1]]), np.array([[1, 5], [0, 0]])]


def test_average_and_max():
    assert np.allclose(AGGREGATIONS["average"](Q, W), [[0.5, -2.0], [2.0, 4.0]])
    assert np.allclose(AGGREGATIONS["max"](Q, W), [[1.0, -1.0], [4.0, 7.0]])


def test_visit_average():
    # entry (0,0): (1*3 + 0.5*1) / 4; (0,1): (-2*4 - 1*2 - 3*5) / 11; (1,0): nobody -> mean
    want = [[3.5 / 4, -25.0 / 11], [2.0, 12.0 / 2]]
    assert np.allclose(AGGREGATIONS["visit_average"](Q, W), want)


def test_max_visited_ignores_unvisited_entries():
    # (0,0): visitors 1 and 3 -> max(1, 0.5); (0,1): all -> -1; (1,0): nobody -> mean 2;
    # (1,1): visitors 1, 2 -> 7. Plain max would keep robot 2's unvisited 0 at (0,0)? no:
    # it is robot 3's 0.5 < 1; at (0,1) all visited; the difference shows with danger values:
    assert np.allclose(AGGREGATIONS["max_visited"](Q, W), [[1.0, -1.0], [2.0, 7.0]])
    danger = [np.array([[-2.0]]), np.array([[0.0]])]
    seen = [np.array([[5]]), np.array([[0]])]
    assert AGGREGATIONS["max"](danger, seen)[0, 0] == 0.0  # the ratchet
    assert AGGREGATIONS["max_visited"](danger, seen)[0, 0] == -2.0  # what was learnt


def test_bad_input_is_refused():
    with pytest.raises(ValueError):
        AGGREGATIONS["average"]([np.array([[np.nan]])], [np.array([[1]])])
    with pytest.raises(ValueError):
        AGGREGATIONS["max"]([np.zeros((2, 2))], [np.zeros((3, 2))])


def test_federate_same_seeds_same_tables():
    cfgs = [TrainerConfig(arena=a, seed=s, iterations=200) for a, s in (("r1", 1), ("r4", 2))]
    a = federate(cfgs, 200, 50, "average", snapshot_every=2)
    b = federate(cfgs, 200, 50, "average", snapshot_every=2)
    assert np.array_equal(a.table, b.table) and np.array_equal(a.q_sum, b.q_sum)
    assert sorted(a.snapshots) == [100, 200]
    assert a.q_sum.shape == (2, 200)


def test_prolog_max_visited_matches_python():
    """platform_pl/dfrl_agent/examples/max_visited.pl, loaded into the agent module, folds the
    same tables as aggregate_max_visited (the study's mirror of the injected method)."""
    import json
    import subprocess
    from pathlib import Path

    swipl = find_swipl()
    if swipl is None:
        pytest.skip("swipl not installed")
    root = Path(__file__).resolve().parents[4] / "platform_pl" / "dfrl_agent"
    tables = ",".join(
        f"qtable_visits([2,2],{json.dumps(q.ravel().tolist())},{json.dumps(w.ravel().tolist())})"
        for q, w in zip(Q, W)
    )
    goal = f"dfrl_agent:aggregate_tables(max_visited,[{tables}],qtable(_,V)),format('~w~n',[V])"
    out = subprocess.run(
        [
            swipl,
            "-q",
            "-g",
            f"use_module('{root / 'dfrl_agent'}')",
            "-g",
            f"consult('{root / 'examples' / 'max_visited'}')",
            "-g",
            goal,
            "-t",
            "halt",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert np.allclose(np.reshape(got, (2, 2)), AGGREGATIONS["max_visited"](Q, W))
