"""Helpers shared by the bridge tests (imported by conftest.py and the test modules)."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import numpy as np

from dfrl.pybridge.providers import StaticTable

HELPER = Path(__file__).with_name("agents_helper.pl")


class ArrayRobot(StaticTable):
    """The bridge's own static table provider, checking what the bridge promises a provider:
    every table it is given is float64, of the registered shape, all finite."""

    def __init__(self, n_states: int, n_actions: int, seed: int = 0) -> None:
        super().__init__((n_states, n_actions), seed)

    def set_q_table(self, table: np.ndarray) -> None:
        assert table.shape == self.shape and table.dtype == np.float64
        assert np.isfinite(table).all()
        super().set_q_table(table)


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
