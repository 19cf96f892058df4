"""Custody of a migrating agent, case by case, with real processes (contract K2).

Two store-backed nodes A and B (``experiments/tools/bench/chaos_node.pl``: reply timeout 1.5 s,
commit timeout 1 s, settle period 0.5 s); A reaches B through a fault proxy. A *parcel* agent
(it counts its arrivals and rests) is moved from A to B once while a fault hits the hand-over;
then the nodes settle by themselves and a census (``custody_agents/2`` on both) must show
exactly one copy, idle, where the protocol says it belongs -- and never two live copies on the
way.
"""

from __future__ import annotations

import signal
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from dfrl.experiments.tools.bench.chaos import ChaosConsole, NodeProcess, Trigger
from dfrl.experiments.tools.bench.fault_proxy import DROP, PASS, FaultProxy

from .conftest import SWIPL, free_port

pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")

LIVE = ("running", "idle")


class Pair:
    """Nodes A (0) and B (1), the proxy A -> B, and a console for census and commands."""

    def __init__(self, work: Path) -> None:
        ports = [free_port(), free_port()]
        self.proxy = FaultProxy(("127.0.0.1", ports[1]))
        self.a = NodeProcess(0, ports[0], work, {1: self.proxy.address[1]})
        self.b = NodeProcess(1, ports[1], work, {0: ports[0]})
        self.a.start([])
        self.b.start([])
        self.console = ChaosConsole()

    def close(self) -> None:
        self.console.close()
        for n in (self.a, self.b):
            n.signal(signal.SIGCONT)
            n.kill()
        self.proxy.close()

    def create(self, name: str = "p1") -> None:
        assert self.console.ask(
            {"op": "create", "port": self.a.port, "agent": name, "kind": "parcel"}
        )["ok"]

    def move(self, name: str = "p1") -> dict:
        return self.console.ask(
            {"op": "move", "port": self.a.port, "agent": name, "to": self.proxy.address[1]}
        )

    def census(self) -> dict[str, list[tuple[str, int]]]:
        """Node ("A"/"B") -> [(status, arrivals)] of the parcel; a node that does not answer
        is missing."""
        answer = self.console.ask({"op": "census", "ports": [self.a.port, self.b.port]})
        out: dict[str, list[tuple[str, int]]] = {}
        for label, node in zip("AB", answer["nodes"]):
            if node["ok"]:
                out[label] = [(x["status"], x["hops"]) for x in node["agents"]]
        return out

    def settle(self, want: Callable[[dict], bool], timeout: float = 15.0) -> dict:
        """Census until ``want`` holds (bounded); every census on the way has < 2 live copies."""
        deadline = time.monotonic() + timeout
        while True:
            c = self.census()
            live = sum(s in LIVE for copies in c.values() for s, _ in copies)
            assert live <= 1, f"two live copies: {c}"
            if want(c) or time.monotonic() > deadline:
                return c
            time.sleep(0.2)


def at_a(c: dict) -> bool:
    return c.get("A") == [("idle", 0)] and c.get("B") == []


def at_b(c: dict) -> bool:
    return c.get("A") == [] and c.get("B") == [("idle", 1)]


@pytest.fixture
def pair(tmp_path: Path) -> Iterator[Pair]:
    p = Pair(tmp_path)
    yield p
    p.close()


def fault(pair: Pair, point: str, action, on_fire: Callable[[], None] = lambda: None) -> Trigger:
    trigger = Trigger(point, action, on_fire)
    pair.proxy.rule(trigger)
    return trigger


def test_plain_move_and_census(pair: Pair) -> None:
    pair.create()
    assert pair.settle(at_a) == {"A": [("idle", 0)], "B": []}
    assert pair.move()["ok"]
    assert at_b(pair.settle(at_b))


def test_destination_killed_after_staged_reply(pair: Pair) -> None:
    pair.create()
    trigger = fault(pair, "staged", PASS, pair.b.kill)
    answer = pair.move()
    assert trigger.fired.wait(5)
    assert answer["ok"], answer  # the source committed: B holds it (on disk)
    assert pair.census()["A"] == []
    pair.proxy.rule(None)
    pair.b.start([])  # recovers the staged parcel, asks A: committed
    assert at_b(pair.settle(at_b))


def test_source_killed_after_commit_decision_before_commit_frame(pair: Pair) -> None:
    pair.create()
    trigger = fault(pair, "commit", DROP, pair.a.kill)
    assert not pair.move()["ok"]  # A died while answering
    assert trigger.fired.wait(5)
    time.sleep(2.0)  # B's commit timeout passes, A cannot be asked
    c = pair.census()
    assert "A" not in c and [s for s, _ in c["B"]] in (["staged"], ["in_doubt"])
    pair.proxy.rule(None)
    pair.a.start([])  # its stored decision says committed
    assert at_b(pair.settle(at_b))


def test_source_killed_before_its_decision(pair: Pair) -> None:
    pair.create()
    fault(pair, "staged", PASS, pair.a.kill)
    assert not pair.move()["ok"]
    pair.proxy.rule(None)
    pair.a.start([])  # no record of the migration: presumed abort
    assert at_a(pair.settle(at_a))


def test_lost_commit(pair: Pair) -> None:
    pair.create()
    fault(pair, "commit", DROP)
    assert pair.move()["ok"]  # decided committed; the commit frame is lost
    pair.proxy.rule(None)
    assert at_b(pair.settle(at_b))


def test_lost_staged_reply(pair: Pair) -> None:
    pair.create()
    fault(pair, "staged", DROP)
    assert not pair.move()["ok"]  # no staged answer: aborted, A keeps it
    pair.proxy.rule(None)
    assert at_a(pair.settle(at_a))  # B asks A, learns aborted, discards


def test_transfer_delayed_beyond_every_timeout(pair: Pair) -> None:
    pair.create()
    pair.proxy.delay(2.5)  # > A's reply timeout (1.5 s) and B's commit timeout
    assert not pair.move()["ok"]
    pair.proxy.delay(0)
    time.sleep(3.0)  # the late transfer reaches B, is staged, then asked about
    assert at_a(pair.settle(at_a))
    assert pair.move()["ok"]  # and the parcel still moves afterwards
    assert at_b(pair.settle(at_b))


def test_sigstopped_destination(pair: Pair) -> None:
    pair.create()
    pair.b.signal(signal.SIGSTOP)
    try:
        assert not pair.move()["ok"]  # A times out: aborted
    finally:
        pair.b.signal(signal.SIGCONT)
    assert at_a(pair.settle(at_a))


def test_restart_of_either_side_with_its_store(pair: Pair) -> None:
    pair.create()
    pair.a.kill()
    pair.a.start([])
    assert at_a(pair.settle(at_a))  # the created parcel came back from A's store
    assert pair.move()["ok"]
    assert at_b(pair.settle(at_b))
    pair.b.kill()
    pair.b.start([])
    assert at_b(pair.settle(at_b))  # the arrived parcel came back from B's store
