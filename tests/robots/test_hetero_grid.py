"""The grid view of a function learner (robots/grid_view.py) and distillation (robots/distill.py):
hand-computed grid points, get = evaluate, set = distil (with its residual), visits, refusals,
determinism, and the linear learner's capacity floor."""

from __future__ import annotations

import numpy as np
import pytest

from dfrl.robots.distill import DistilConfig, distil
from dfrl.robots.dqn import DQN, DQNConfig
from dfrl.robots.features import feature_matrix
from dfrl.robots.grid_view import GridView, grid_points, grid_table
from dfrl.robots.linear import LinearQ
from dfrl.robots.state import DiscretisationConfig, Discretiser
from dfrl.robots.td import LearnerParams
from dfrl.robots.training import Trainer, TrainerConfig


def _dqn(seed: int = 0) -> DQN:
    return DQN(
        8, 3, LearnerParams(), np.random.default_rng(seed), config=DQNConfig(hidden=(32, 32))
    )


def test_grid_points_are_cell_centres_that_map_back() -> None:
    d = Discretiser()  # four groups x 3 levels: 81 states
    pts = grid_points(d)
    assert pts.shape == (81, 8)
    # state 1: group 0 (sensor 2) at level 1 -> the middle of (0, 0.5]
    assert pts[1].tolist() == [0, 0, 0.25, 0, 0, 0, 0, 0]
    # state 6 = 2 * 3: group 1 (sensors 0 and 1) at level 2 -> the middle of (0.5, 1]
    assert pts[6].tolist() == [0.75, 0.75, 0, 0, 0, 0, 0, 0]
    # state 80: every group at level 2; the rear sensors 3 and 4 read nothing
    assert pts[80].tolist() == [0.75, 0.75, 0.75, 0, 0, 0.75, 0.75, 0.75]
    for cfg in (
        DiscretisationConfig(),
        DiscretisationConfig("three", 4),
        DiscretisationConfig("eight", 2),
    ):
        disc = Discretiser(cfg)
        assert [disc(p) for p in grid_points(disc)] == list(range(disc.n_states))


def test_distil_moves_the_values_towards_the_targets_deterministically() -> None:
    x = grid_points(Discretiser())
    rng = np.random.default_rng(5)
    targets = rng.normal(0.0, 3.0, (81, 3))
    a, b = _dqn(1), _dqn(1)
    before = a.q_batch(x)
    ra = distil(a, x, targets, config=DistilConfig(steps=200))
    distil(b, x, targets, config=DistilConfig(steps=200))
    assert ra.steps == 200
    assert ra.rms_before == pytest.approx(np.sqrt(np.mean((before - targets) ** 2)))
    after = a.q_batch(x)
    assert ra.rms_after == pytest.approx(np.sqrt(np.mean((after - targets) ** 2)))
    assert ra.rms_after < 0.3 * ra.rms_before
    assert np.array_equal(a.get_params(), b.get_params())  # same start, same result
    assert all(np.array_equal(o, t) for o, t in zip(a.online, a.target))  # target synced
    # already there: no step taken
    r0 = distil(a, x, after, config=DistilConfig(steps=50, stop_rms=1e-9))
    assert r0.steps == 0 and r0.rms_after == 0.0
    with pytest.raises(ValueError, match="targets of shape"):
        distil(a, x, targets[:, :2])
    with pytest.raises(ValueError, match="non-finite"):
        distil(a, x, np.full((81, 3), np.nan))


def test_linear_fits_a_sum_of_per_sensor_functions_but_not_any_table() -> None:
    x = grid_points(Discretiser())
    # a table a linear learner can hold: the values of other weights
    other = LinearQ(8, 3, LearnerParams(), np.random.default_rng(0))
    other.weights[...] = np.random.default_rng(3).normal(0.0, 0.3, other.weights.shape)
    reachable = grid_table(other, Discretiser())
    lin = LinearQ(8, 3, LearnerParams(), np.random.default_rng(0))
    report = distil(lin, x, reachable, config=DistilConfig(steps=2000, stop_rms=1e-3))
    assert report.rms_after <= 1e-3
    # a table that is no sum of per-sensor functions: the residual stops at the least-squares
    # floor of the features (computed here with numpy's solver), well above zero
    table = np.zeros((81, 3))
    table[80] = 10.0  # only when every group is near
    phi = feature_matrix(x, lin.coding)
    floor = np.sqrt(np.mean((phi @ np.linalg.lstsq(phi, table, rcond=None)[0] - table) ** 2))
    lin2 = LinearQ(8, 3, LearnerParams(), np.random.default_rng(0))
    rep2 = distil(lin2, x, table, config=DistilConfig(steps=2000, stop_rms=0.0))
    assert floor > 0.3
    assert rep2.rms_after == pytest.approx(floor, rel=0.05)


def test_grid_view_of_a_trainer() -> None:
    cfg = TrainerConfig(
        arena="r1", algo="dqn", seed=2, dqn=DQNConfig(learning_starts=20, batch_size=8)
    )
    with Trainer(cfg) as t:
        view = GridView(t)
        states, actions = [], []
        for _ in range(60):
            m = t.step()
            states.append(m.state)
            actions.append(m.action)
        # visits: one per transition learnt from, at its (state, action)
        expected = np.zeros((81, 3), dtype=np.int64)
        np.add.at(expected, (states, actions), 1)
        assert np.array_equal(view.visits, expected) and view.visits.sum() == 60
        # get: the network at the grid points
        q = view.q_table
        assert q.shape == (81, 3)
        assert np.array_equal(q, t.learner.q_batch(grid_points(t.discretiser)))
        # set: distilled, the residual kept; the parameters pass through
        target = q + np.where(np.arange(81)[:, None] % 2 == 0, 1.0, -1.0)
        view.set_q_table(target)
        rep = view.last_distillation
        assert rep is not None and rep.rms_before == pytest.approx(1.0)
        assert rep.rms_after < 0.1
        assert np.sqrt(np.mean((view.q_table - target) ** 2)) == pytest.approx(rep.rms_after)
        assert np.array_equal(view.params, t.params) and view.learner_kind == "function"
        # refused writes leave the network as it is
        p = t.params
        with pytest.raises(ValueError, match="does not match the grid's"):
            view.set_q_table(np.zeros((81, 4)))
        with pytest.raises(ValueError, match="non-finite"):
            view.set_q_table(np.full((81, 3), np.inf))
        assert np.array_equal(t.params, p)
        t.step()  # learning goes on after a share


def test_grid_view_refuses_a_tabular_learner() -> None:
    with Trainer(TrainerConfig(arena="r1", algo="qlearning", seed=1)) as t:
        with pytest.raises(TypeError, match="for a function learner"):
            GridView(t)


def test_the_bridge_takes_a_grid_view_as_a_table() -> None:
    from dfrl.pybridge import StaticParams
    from dfrl.pybridge.providers import provider_offer

    with Trainer(TrainerConfig(arena="r1", algo="linear", seed=1)) as t:
        view = GridView(t)
        assert provider_offer(view, (81, 3)) == ("function", (81, 3), [("w", (3, 257))])
        assert provider_offer(view) == ("function", None, [("w", (3, 257))])  # params only
    # a function learner without a table view cannot be given a table shape
    with pytest.raises(ValueError, match="offers a table view"):
        provider_offer(StaticParams([("w", (2, 3))]), (81, 3))
