"""The in-process federation of :mod:`.fedsim` on the batched simulator.

:func:`federate_batched` is :func:`.fedsim.federate` with every robot of the federation in one
:class:`~dfrl.robots.batched.training.BatchedTrainer`: the robots are stepped together in
compiled code up to the next share or observation (whichever comes first), then the same
aggregation (:data:`.fedsim.AGGREGATIONS`, in the config's robot order) folds ``bt.q`` with
``bt.visits`` and every robot gets the aggregate, exactly as at the end of that iteration of
:func:`.fedsim.federate`. The robots do not interact between two shares, so stepping them in
chunks changes nothing (tested against one iteration at a time).

Observers and share hooks receive :class:`BatchedRobot` objects, one per robot, which offer
what they read of a :class:`~dfrl.robots.training.Trainer`: ``q_table`` and ``visits`` (live
views), ``collisions``, ``respawns``, ``cumulative_reward``, ``iteration``, ``config`` and
``set_q_table``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from dfrl.experiments.science.studies.fedsim import AGGREGATIONS, Federation
from dfrl.robots.batched.training import BatchedTrainer
from dfrl.robots.training import TrainerConfig


class BatchedRobot:
    """Robot ``index`` of a :class:`BatchedTrainer`, seen as a trainer.

    Parameters
    ----------
    trainer : BatchedTrainer
    index : int
    """

    def __init__(self, trainer: BatchedTrainer, index: int) -> None:
        self.trainer, self.index = trainer, index

    @property
    def config(self) -> TrainerConfig:
        return self.trainer.configs[self.index]

    @property
    def q_table(self) -> np.ndarray:
        """The live table, shape (n_states, n_actions) (writes go straight in)."""
        return self.trainer.q[self.index]

    @property
    def visits(self) -> np.ndarray:
        """Update counts, int64, shape (n_states, n_actions)."""
        return self.trainer.visits[self.index]

    def set_q_table(self, table: np.ndarray) -> None:
        """Replace the table (checked), keeping the action already chosen."""
        self.trainer.set_table(self.index, table)

    @property
    def iteration(self) -> int:
        return self.trainer.iteration

    @property
    def collisions(self) -> int:
        return int(self.trainer.collisions[self.index])

    @property
    def respawns(self) -> int:
        return int(self.trainer.respawns[self.index])

    @property
    def cumulative_reward(self) -> float:
        return float(self.trainer.cumulative_reward[self.index])


#: :data:`.fedsim.Observer` and :data:`.fedsim.ShareHook` for batched robots.
BatchedObserver = Callable[[int, Sequence[BatchedRobot]], bool]
BatchedShareHook = Callable[[int, Sequence[BatchedRobot]], None]


def next_stop(i: int, iterations: int, respite: int, observe_every: int) -> int:
    """The first iteration after ``i`` at which the federation shares, observes or ends
    (``observe_every`` 0: no observer)."""
    stop = min(iterations, (i // respite + 1) * respite)
    if observe_every:
        stop = min(stop, (i // observe_every + 1) * observe_every)
    return stop


def federate_batched(
    configs: Sequence[TrainerConfig],
    iterations: int,
    respite: int,
    method: str = "average",
    snapshot_every: int = 0,
    initial: np.ndarray | None = None,
    observe: BatchedObserver | None = None,
    observe_every: int = 0,
    final_share: bool = True,
    on_share: BatchedShareHook | None = None,
) -> Federation:
    """:func:`.fedsim.federate` on the batched simulator (the same parameters and outcome;
    no per-step hook).

    Raises
    ------
    KeyError
        Unknown method.
    ValueError
        Bad budget, tables of different shapes, or configs the batched simulator cannot run
        together (:class:`~dfrl.robots.batched.training.BatchError`: a learner without a
        table, a learning control, or robots that differ in what the batch shares).
    ArenaError
        An arena with no free pose left for a respawn.
    """
    agg = AGGREGATIONS[method]
    if iterations < 1 or respite < 1:
        raise ValueError("iterations and respite must be >= 1")
    if observe is not None and observe_every < 1:
        raise ValueError("an observer needs observe_every >= 1")
    bt = BatchedTrainer(configs)
    if initial is not None:
        bt.set_tables(initial)
    robots = [BatchedRobot(bt, k) for k in range(bt.n)]
    q_sum = np.zeros((bt.n, iterations))
    reward = np.zeros((bt.n, iterations))
    snaps: dict[int, np.ndarray] = {}
    rounds, i, done = 0, 0, iterations
    while i < iterations:
        stop = next_stop(i, iterations, respite, observe_every if observe is not None else 0)
        before = bt.cumulative_reward
        rec = bt.run(stop - i, record=True)
        assert rec is not None
        q_sum[:, i:stop] = rec.q_sum
        # summed one step after the other, as Trainer.step adds each reward to the total
        reward[:, i:stop] = np.cumsum(np.column_stack([before, rec.reward]), axis=1)[:, 1:]
        i = stop
        if i % respite == 0 or (final_share and i == iterations):
            table = agg(list(bt.q), list(bt.visits))
            bt.set_tables(table)
            if on_share is not None:
                on_share(i, robots)
            rounds += 1
            if (snapshot_every and rounds % snapshot_every == 0) or i == iterations:
                snaps[i] = table.copy()
        if observe is not None and i % observe_every == 0 and observe(i, robots):
            done = i
            break
    return Federation(
        table=bt.q[0].copy(),
        visits=bt.visits.sum(axis=0),
        snapshots=snaps,
        q_sum=q_sum[:, :done],
        reward=reward[:, :done],
        collisions=bt.collisions.copy(),
        iterations=done,
    )


def in_turn_batched(config: TrainerConfig, arenas: Sequence[str], iterations: int) -> np.ndarray:
    """:func:`.fedsim.in_turn` on the batched simulator: one robot trained ``iterations`` steps
    in each of ``arenas`` in turn (seed ``config.seed + 1000 k`` in arena k), keeping its
    table; the final table."""
    if not arenas:
        raise ValueError("no arena given")
    table: np.ndarray | None = None
    for k, arena in enumerate(arenas):
        bt = BatchedTrainer([config.replace(arena=arena, seed=config.seed + 1000 * k)])
        if table is not None:
            bt.set_table(0, table)
        bt.run(iterations)
        table = bt.q[0].copy()
    assert table is not None
    return table
