"""An unreachable stop is skipped within the agent's skip time; a healed stop is visited again
with no stale copy in the way (issue 20).

A stop is frozen with ``SIGSTOP`` for longer than the skip time (its kernel still accepts the
agent's transfer, which it stages late, on ``SIGCONT``, after its source gave up: the stale copy
the next round meets). Real ``swipl`` processes on loopback (``test_resting_holder.Stops``).

Control (the behaviour before): a skip time above the nodes' reply timeout gives the stall of
before (one reply timeout); the flag ``dfrl_replace_stale`` false on the healed stop keeps the
stale copy, and a later round is refused there with "No permission to create agent".
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest

from .conftest import SWIPL, Proc
from .test_resting_holder import SLACK_S, Stops, report, rounds_once

pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")

REPLY_S = 4.0  # the stops' reply timeout: what a frozen stop cost before


def freeze_second_round(
    stops: Stops,
    skip_after: float,
    hold_s: float,
    *,
    rest: float = 0.6,
    rounds: int = 4,
    retries: int = 2,
) -> tuple[float, float]:
    """Launch, freeze r2 right after round 1 until round 2 is logged and at least ``hold_s``,
    thaw it; return (frozen, thawed)."""
    stops.launch(
        rounds=rounds, rest=rest, options=f"[skip_after({skip_after}), retries({retries})]"
    )
    stops.wait(lambda: stops.events("round"), 20, "round 1")
    pid = stops.nodes[2].popen.pid
    frozen = time.time()
    os.kill(pid, signal.SIGSTOP)
    try:
        stops.wait(lambda: len(stops.events("round")) >= 2, hold_s + 30, "round 2")
        time.sleep(max(0.0, hold_s - (time.time() - frozen)))
    finally:
        os.kill(pid, signal.SIGCONT)
    return frozen, time.time()


def skip_of(r: dict, robot: str) -> dict | None:
    return next((s for s in r["skipped"] if s["robot"] == robot), None)


def test_frozen_stop_skipped_in_bound_then_visited_again(tmp_path: Path, procs: list[Proc]) -> None:
    # Prepare: four stops, skip time 1.5 s (well under the nodes' 4 s reply timeout).
    skip = 1.5
    stops = Stops(tmp_path, procs, [0.0] * 4, reply_s=REPLY_S)
    # Execute: freeze r2 from the end of round 1 to the end of round 2, then thaw it.
    freeze_second_round(stops, skip, hold_s=0.0)
    stops.wait(lambda: stops.events("finished"), 40, "the end of the tour")
    # Assert: round 2 skipped r2 after at most the skip time (the reason says how long), did not
    # wait for it again on the way back, and took at most the skip time more than a round;
    # every later round visited r2 again: no stale copy refused the agent; tables equal.
    rounds = rounds_once(stops, 4)
    r2 = rounds[1]
    s = skip_of(r2, "r2")
    assert s is not None and "skipped after" in s["reason"], r2
    waited = float(s["reason"].split("skipped after ")[1].split(" s")[0])
    report("frozen stop: skipped after (s)", waited)
    assert waited <= skip + 0.3, s
    duration = r2["end"] - r2["start"]
    report("frozen stop: round with the skip took (s)", duration)
    assert duration < skip + SLACK_S, duration
    for r in rounds[2:]:
        assert r["visited"] == ["r0", "r1", "r2", "r3"], r
        assert r["skipped"] == [], r
    text = "\n".join(json_line for p in stops.nodes for json_line in p.lines)
    assert "No permission to create agent" not in text
    tables = [stops.table(i) for i in range(4)]
    assert all(t == tables[0] for t in tables), tables
    assert not any(stops.has_agent(i) for i in range(4))


def test_frozen_stop_control_before(tmp_path: Path, procs: list[Proc]) -> None:
    # Control, the behaviour before on both counts: a skip time above the reply timeout, so the
    # frozen stop costs one reply timeout; and the flag dfrl_replace_stale false, so the healed
    # stop keeps the stale copy and a later round is refused there with "No permission to create
    # agent".
    stops = Stops(tmp_path, procs, [0.0] * 4, reply_s=REPLY_S, legacy=True)
    freeze_second_round(stops, 30, hold_s=REPLY_S + 1.5, rounds=4, retries=0)
    stops.wait(lambda: stops.events("finished"), 40, "the end of the tour")
    rounds = rounds_once(stops, 4)
    r2 = rounds[1]
    assert skip_of(r2, "r2") is not None, r2
    report("control (before): round with the frozen stop took (s)", r2["end"] - r2["start"])
    assert r2["end"] - r2["start"] >= REPLY_S - 0.5, r2
    refused = [
        r
        for r in rounds[2:]
        if (s := skip_of(r, "r2")) is not None and "No permission to create agent" in s["reason"]
    ]
    assert refused, rounds
    report("control (before): later rounds refused by the stale copy", len(refused))
