"""The bridge serving a real learner (robots.training.Trainer) while it trains."""

from __future__ import annotations

import time

import numpy as np
import pytest
from bridge_helpers import agent_result, spawn

from dfrl.pybridge import Atom, Term, Var

training = pytest.importorskip("dfrl.robots.training")


def test_agent_reads_and_writes_a_training_robot(node) -> None:
    trainer = training.Trainer(training.TrainerConfig(seed=3))
    try:
        for _ in range(20):
            trainer.step()
        node.register_robot("epuck1", trainer, algo=trainer.config.algo)
        # the agent reads the table, then writes it back halved
        half = Term(">>", [Var("X"), Var("Y")], Term("is", Var("Y"), Term("/", Var("X"), 2)))
        goal = Term(
            ",",
            Term("get_qtable", Atom("epuck1"), Term("qtable", Var("S"), Var("V"))),
            Term(
                ",",
                Term("maplist", half, Var("V"), Var("W")),
                Term("set_qtable", Atom("epuck1"), Term("qtable", Var("S"), Var("W"))),
            ),
        )
        spawn(node, "trainer_agent", goal)
        snapshots = []
        deadline = time.monotonic() + 10
        result = None
        while result is None and time.monotonic() < deadline:
            trainer.step()  # sense -> learn -> act
            before = trainer.q_table.copy()
            if node.serve_pending():  # between two learning steps
                snapshots.append((before, trainer.q_table.copy()))
            result = node.call(
                "agent_result", Atom("trainer_agent"), Var("R"), module="bridge_test_agents"
            )
        assert result is not None and result["R"].name == "true", result
        get_goal = result["R"].args[0][0]  # (Get, Maplist, Set) comes back as a tuple
        read = np.array(get_goal.args[1].args[1], dtype=np.float64)
        # what the agent read is the table as it was between two learning steps
        assert any(np.array_equal(read, b.reshape(-1)) for b, _ in snapshots)
        # and its write replaced the table at once, exactly
        assert any(np.array_equal(a, read.reshape(a.shape) / 2) for _, a in snapshots)
        assert dict(node.robots())[Atom("epuck1")][1] == Term("shape", list(trainer.q_table.shape))
        for _ in range(5):
            trainer.step()  # training goes on with the new table
    finally:
        trainer.close()


def test_visits_of_a_training_robot(node) -> None:
    trainer = training.Trainer(training.TrainerConfig(seed=4))
    try:
        for _ in range(30):
            trainer.step()
        node.register_robot("epuck2", trainer)
        spawn(node, "visits_agent", Term("get_visits", Atom("epuck2"), Var()))
        result = agent_result(node, "visits_agent", serve=True)
        values = np.array(result.args[0].args[1].args[1], dtype=np.float64)
        assert np.array_equal(values, trainer.visits.reshape(-1).astype(np.float64))
        assert values.sum() > 0
    finally:
        trainer.close()
