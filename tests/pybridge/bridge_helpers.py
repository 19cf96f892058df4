"""Helpers shared by the bridge tests (imported by conftest.py and the test modules)."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

HELPER = Path(__file__).with_name("agents_helper.pl")


class ArrayRobot:
    """A table provider backed by numpy arrays (what a robot's learner offers)."""

    def __init__(self, n_states: int, n_actions: int, seed: int = 0) -> None:
        rng = np.random.default_rng(seed)
        self._q = rng.standard_normal((n_states, n_actions))
        self._visits = rng.integers(0, 1000, (n_states, n_actions), dtype=np.int64)
        self.sets = 0

    @property
    def q_table(self) -> np.ndarray:
        return self._q.copy()

    @property
    def visits(self) -> np.ndarray:
        return self._visits.copy()

    def set_q_table(self, table: np.ndarray) -> None:
        assert table.shape == self._q.shape and table.dtype == np.float64
        self._q = table.copy()
        self.sets += 1


def _atom(text: str) -> Any:
    from dfrl.pybridge import Atom

    return Atom(text)


_counter = iter(range(10**9))


def run_agent(node: Any, goal: Any, timeout: float = 10.0, serve: bool = True) -> Any:
    """Run goal in a new Prolog thread while this (main) thread serves bridge requests
    like a control loop; return true(Goal) / false / error(E) as Python terms."""
    from dfrl.pybridge import Atom, Var

    alias = Atom(f"test_agent_{next(_counter)}")
    node.call("spawn", alias, goal, module="bridge_test_agents")
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if serve:
            node.serve_pending()
        sol = node.call("agent_result", alias, Var("R"), module="bridge_test_agents")
        if sol is not None:
            return sol["R"]
        time.sleep(0.001)
    raise AssertionError(f"agent {alias} did not finish in {timeout} s")


def spawn(node: Any, alias: str, goal: Any) -> None:
    """Start goal in a Prolog thread named alias (outcome: :func:`agent_result`)."""
    from dfrl.pybridge import Atom

    node.call("spawn", Atom(alias), goal, module="bridge_test_agents")


def agent_result(node: Any, alias: str, timeout: float = 5.0, serve: bool = False) -> Any:
    """Wait for the outcome of a spawned agent (true(Goal) / false / error(E))."""
    from dfrl.pybridge import Atom, Var

    deadline = time.monotonic() + timeout
    while True:
        if serve:
            node.serve_pending()
        sol = node.call("agent_result", Atom(alias), Var("R"), module="bridge_test_agents")
        if sol is not None:
            return sol["R"]
        if time.monotonic() > deadline:
            raise AssertionError(f"agent {alias} did not finish in {timeout} s")
        time.sleep(0.001)
