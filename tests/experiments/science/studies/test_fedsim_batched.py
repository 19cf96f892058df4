"""The federation on the batched simulator: stepped in chunks, it is the federation stepped one
iteration at a time; observers, snapshots and the final share as in fedsim.federate; the
simulator chosen by name."""

from __future__ import annotations

import numpy as np
import pytest

from dfrl.experiments.science.studies import fedsim, simulators
from dfrl.experiments.science.studies.fedsim import AGGREGATIONS
from dfrl.experiments.science.studies.fedsim_batched import (
    federate_batched,
    in_turn_batched,
    next_stop,
)
from dfrl.robots.batched.training import SIM_NAME, BatchedTrainer, BatchError
from dfrl.robots.training import TrainerConfig

CFGS = [TrainerConfig(arena=a, seed=s, iterations=230) for a, s in (("r1", 1), ("r4", 2))]


def one_at_a_time(configs, iterations, respite, method):
    """The federation by hand: every robot one iteration, the share at every respite and
    after the last iteration."""
    bt = BatchedTrainer(configs)
    q_sum = np.zeros((bt.n, iterations))
    reward = np.zeros((bt.n, iterations))
    snaps = {}
    for i in range(1, iterations + 1):
        rec = bt.run(1, record=True)
        q_sum[:, i - 1] = rec.q_sum[:, 0]
        reward[:, i - 1] = bt.cumulative_reward
        if i % respite == 0 or i == iterations:
            table = AGGREGATIONS[method](list(bt.q), list(bt.visits))
            bt.set_tables(table)
            snaps[i] = table.copy()
    return bt, q_sum, reward, snaps


@pytest.mark.parametrize("method", ["average", "visit_average"])
def test_chunks_are_one_iteration_at_a_time(method: str) -> None:
    seen: list[int] = []
    fed = federate_batched(
        CFGS,
        230,
        50,
        method,
        snapshot_every=1,
        observe=lambda it, robots: seen.append(it) or False,
        observe_every=40,
    )
    bt, q_sum, reward, snaps = one_at_a_time(CFGS, 230, 50, method)
    assert seen == [40, 80, 120, 160, 200]
    assert np.array_equal(fed.table, bt.q[0]) and np.array_equal(fed.visits, bt.visits.sum(0))
    assert np.array_equal(fed.q_sum, q_sum) and np.array_equal(fed.reward, reward)
    assert sorted(fed.snapshots) == [50, 100, 150, 200, 230]
    assert all(np.array_equal(fed.snapshots[k], snaps[k]) for k in snaps)
    assert np.array_equal(fed.collisions, bt.collisions) and fed.iterations == 230


def test_observers_see_the_robots_after_the_share() -> None:
    looks: dict[int, list[np.ndarray]] = {}

    def observe(it, robots):
        looks[it] = [r.q_table.copy() for r in robots]
        assert all(r.iteration == it for r in robots)
        assert robots[1].config.arena == "r4" and robots[0].collisions >= 0
        return it >= 200

    fed = federate_batched(CFGS, 300, 100, observe=observe, observe_every=50)
    assert sorted(looks) == [50, 100, 150, 200] and fed.iterations == 200
    assert fed.q_sum.shape == fed.reward.shape == (2, 200)
    assert not np.array_equal(*looks[50])  # between shares the robots differ
    assert np.array_equal(*looks[100])  # a share gives both the average
    # the final share is optional, as in fedsim.federate: shares at 100 and 200 only
    apart = federate_batched(CFGS, 250, 100, final_share=False, snapshot_every=1)
    assert sorted(apart.snapshots) == [100, 200]
    with pytest.raises(ValueError, match="observe_every"):
        federate_batched(CFGS, 100, 50, observe=lambda it, r: False)


def test_initial_table_and_what_cannot_be_batched() -> None:
    start = np.full((81, 3), 0.5)
    fed = federate_batched(CFGS[:1], 10, 100, initial=start, final_share=False)
    assert (fed.table[fed.visits == 0] == 0.5).all()  # what was never updated started there
    assert (fed.table[fed.visits > 0] != 0.5).any()
    with pytest.raises(BatchError, match="not batched"):
        federate_batched([CFGS[0].replace(algo="dqn")], 10, 5)
    with pytest.raises(KeyError):
        federate_batched(CFGS, 10, 5, method="median")


def test_in_turn_keeps_the_table_across_arenas() -> None:
    a = in_turn_batched(CFGS[0], ["r1", "r2"], 60)
    assert np.array_equal(a, in_turn_batched(CFGS[0], ["r1", "r2"], 60))
    first = BatchedTrainer([CFGS[0].replace(arena="r1")])
    first.run(60)
    second = BatchedTrainer([CFGS[0].replace(arena="r2", seed=CFGS[0].seed + 1000)])
    second.set_table(0, first.q[0])
    second.run(60)
    assert np.array_equal(a, second.q[0])


def test_next_stop_and_the_simulators_by_name() -> None:
    assert next_stop(0, 230, 50, 40) == 40 and next_stop(40, 230, 50, 40) == 50
    assert next_stop(200, 230, 50, 0) == 230 and next_stop(0, 30, 50, 0) == 30
    assert simulators.BATCHED == SIM_NAME and simulators.DEFAULT_SIM == SIM_NAME
    assert simulators.federator("pybullet") is fedsim.federate
    assert simulators.federator("batched") is federate_batched
    with pytest.raises(ValueError, match="sim: one of batched, pybullet"):
        simulators.federator("mujoco")
    with pytest.raises(simulators.SimulatorMismatch, match="ran on the pybullet simulator"):
        simulators.check_same("pybullet", "batched", "runs.jsonl:3")
