"""Node-wide budgets (issue 16): many bombs at once stay within what the node allows in all
(max_running_agents x agent_stack_limit, the memory budget, the frame size), real processes;
helpers in bounds_helpers.py. Each test has a control that would fail if the bound were too tight.
"""

from __future__ import annotations

import re
import threading
import time
from pathlib import Path

import pytest

from tests.platform.conftest import SWIPL, Proc
from tests.security.bounds_helpers import MIB, attacker, start_victim, status

pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")


def wait_rss_settled(pid: int, base_kb: int, within_kb: int, limit_s: float = 10.0) -> int:
    """VmRSS of ``pid`` (kB) once it is within ``within_kb`` of ``base_kb``, or after
    ``limit_s`` seconds."""
    end = time.monotonic() + limit_s
    rss = status(pid, "VmRSS")
    while rss - base_kb > within_kb and time.monotonic() < end:
        time.sleep(0.2)
        rss = status(pid, "VmRSS")
    return rss


def concurrent_bombs(
    procs: list[Proc], tmp_path: Path, port: int, handler: str, clauses: str, n: int = 8
) -> Proc:
    """An attacker that sends ``n`` agents with ``handler`` at once (b1..bn), waits for the
    victim's report on each, then sends an ordinary agent g1."""
    names = [f"b{i}" for i in range(1, n + 1)]
    sends = "".join(f"send({b}, {handler}, {port}), " for b in names)
    awaits = "".join(f"await_report({b}, 40), " for b in names)
    return attacker(
        procs,
        tmp_path,
        clauses,
        f"""
        get_time(T0), {sends}
        {awaits}
        get_time(T1), D is T1 - T0, format("ALL STOPPED after ~3f s~n", [D]),
        send(g1, good, {port}),
    """,
    )


def test_eight_memory_bombs_within_node_budget(tmp_path: Path, procs: list[Proc]) -> None:
    # defaults: agent_stack_limit 256 MiB, agent_memory_budget 1 GiB, max_running_agents 8.
    # The CPU bound is raised to 30 s (as for the assert bombs below): under a CPU hog a bomb
    # spent 2 s of CPU (building and collecting its list) before it reached a memory bound,
    # and was stopped by the CPU bound, which is another test's claim.
    # the 8 bombs come from one peer: max_running_per_peer (4) would run only 4 at once, so it
    # is off here, for the node-wide bounds to meet 8
    victim, port = start_victim(
        procs, tmp_path, "agent_cpu_limit(30), max_running_per_peer(infinite)"
    )
    pid = victim.popen.pid
    time.sleep(0.3)
    base = status(pid, "VmRSS")
    a = concurrent_bombs(
        procs,
        tmp_path,
        port,
        "bomb",
        """
    :- dynamic bomb/3.
    bomb(guid, _, main) :- numlist(1, 200000000, L), length(L, N), N > 0.
    """,
    )
    a.wait_for("DONE", 120)
    out = a.output()
    kinds = re.findall(r"REPORT b\d+ (\w+)\(", out)
    assert len(kinds) == 8 and set(kinds) <= {"memory", "memory_budget"}, out
    hwm = status(pid, "VmHWM")
    victim.wait_for("GOOD at", 20)
    after = wait_rss_settled(pid, base, 50 * 1024)
    print(
        f"8 memory bombs: {a.wait_for('ALL STOPPED')}, stopped by {sorted(kinds)}; RSS before "
        f"{base // 1024} MiB, peak +{(hwm - base) // 1024} MiB, after +{(after - base) // 1024} MiB"
    )
    # the stated bound (README "Bounds on agents"), the hard one: stacks never exceed
    # max_running_agents x agent_stack_limit (8 x 256 MiB), plus 256 MiB for the node itself.
    # The budget (1 GiB, enforced by the monitor) keeps it lower when the monitor gets the CPU:
    # +443..+541 MiB on a quiet machine, +1720 MiB with stress-ng --cpu 2 beside it
    assert (hwm - base) * 1024 < 8 * 256 * MIB + 256 * MIB, (base, hwm)
    assert (after - base) < 50 * 1024, (base, after)


def test_eight_assert_bombs_within_node_budget(tmp_path: Path, procs: list[Proc]) -> None:
    # the 8 bombs come from one peer: max_running_per_peer (4) would run only 4 at once, so it
    # is off here, for the node-wide bounds to meet 8
    victim, port = start_victim(
        procs, tmp_path, "agent_cpu_limit(30), max_running_per_peer(infinite)"
    )
    pid = victim.popen.pid
    time.sleep(0.3)
    base = status(pid, "VmRSS")
    a = concurrent_bombs(
        procs,
        tmp_path,
        port,
        "asserter",
        """
    :- dynamic asserter/3.
    asserter(guid, _, main) :- between(1, inf, I), assertz(fact(I)), fail.
    """,
    )
    a.wait_for("DONE", 180)
    out = a.output()
    kinds = re.findall(r"REPORT b\d+ (\w+)\(", out)
    assert len(kinds) == 8 and set(kinds) <= {"module_memory", "memory_budget"}, out
    hwm = status(pid, "VmHWM")
    victim.wait_for("GOOD at", 20)
    after = wait_rss_settled(pid, base, 50 * 1024)
    print(
        f"8 assert bombs: {a.wait_for('ALL STOPPED')}, stopped by {sorted(kinds)}; RSS before "
        f"{base // 1024} MiB, peak +{(hwm - base) // 1024} MiB, after +{(after - base) // 1024} MiB"
    )
    assert (hwm - base) * 1024 < 1024 * MIB + 512 * MIB, (base, hwm)
    assert (after - base) < 50 * 1024, (base, after)


def test_assert_bombs_stopped_by_node_budget(tmp_path: Path, procs: list[Proc]) -> None:
    # a budget below the sum of the module limits (8 x 64 MiB): the budget stops them
    victim, port = start_victim(
        procs,
        tmp_path,
        "agent_cpu_limit(30), agent_memory_budget(268435456), max_running_per_peer(infinite)",
    )  # see above
    pid = victim.popen.pid
    time.sleep(0.3)
    base = status(pid, "VmRSS")
    a = concurrent_bombs(
        procs,
        tmp_path,
        port,
        "asserter",
        """
    :- dynamic asserter/3.
    asserter(guid, _, main) :- between(1, inf, I), assertz(fact(I)), fail.
    """,
    )
    a.wait_for("DONE", 180)
    kinds = re.findall(r"REPORT b\d+ (\w+)\(", a.output())
    assert len(kinds) == 8 and "memory_budget" in kinds, a.output()
    hwm = status(pid, "VmHWM")
    victim.wait_for("GOOD at", 20)
    print(
        f"8 assert bombs, budget 256 MiB: stopped by {sorted(kinds)}; "
        f"RSS peak +{(hwm - base) // 1024} MiB"
    )
    # facts take about 1.15 x their predicate_property size in RSS, and the calls grow until
    # the monitor's next tick, which comes late on a loaded machine (+559 MiB was seen while
    # the whole suite ran): the stated bound is the budget plus 8 slots x 64 MiB
    assert (hwm - base) * 1024 < 256 * MIB + 512 * MIB, (base, hwm)


def test_running_slots_bound_stacks(tmp_path: Path, procs: list[Proc]) -> None:
    # no budget: only max_running_agents(2) x agent_stack_limit(128 MiB) bounds the stacks
    victim, port = start_victim(
        procs,
        tmp_path,
        "agent_memory_budget(infinite), max_running_agents(2), agent_stack_limit(134217728)",
    )
    pid = victim.popen.pid
    time.sleep(0.3)
    base = status(pid, "VmRSS")
    a = concurrent_bombs(
        procs,
        tmp_path,
        port,
        "bomb",
        """
    :- dynamic bomb/3.
    bomb(guid, _, main) :- numlist(1, 200000000, L), length(L, N), N > 0.
    """,
    )
    a.wait_for("DONE", 180)
    kinds = re.findall(r"REPORT b\d+ (\w+)\(", a.output())
    assert kinds == ["memory"] * 8, a.output()
    hwm = status(pid, "VmHWM")
    victim.wait_for("GOOD at", 20)
    print(
        f"8 memory bombs, 2 slots of 128 MiB: {a.wait_for('ALL STOPPED')}; "
        f"RSS peak +{(hwm - base) // 1024} MiB"
    )
    assert (hwm - base) * 1024 < 2 * 128 * MIB + 128 * MIB, (base, hwm)


def test_two_max_size_frames_bounded(tmp_path: Path, procs: list[Proc]) -> None:
    from dfrl.experiments.tools.bench.hostile_auth_attacks import _Conn, _frame

    victim, port = start_victim(procs, tmp_path)  # max_frame_size: 32 MiB
    pid = victim.popen.pid
    time.sleep(0.3)
    base = status(pid, "VmRSS")
    head, tail = b'post(nobody, x, x, ["', b'"]) .\n'
    size = 32 * MIB - 64
    frame = _frame(head + b"a" * (size - len(head) - len(tail)) + tail)
    replies: list[str | None] = []

    def send() -> None:
        c = _Conn(port, 5, timeout=60)
        c.sock.sendall(frame)
        replies.append(c.read())
        c.close()

    ts = [threading.Thread(target=send) for _ in range(2)]
    for t in ts:
        t.start()
    for t in ts:
        t.join(90)
    hwm = status(pid, "VmHWM")
    print(f"2 frames of 32 MiB (a string): RSS peak +{(hwm - base) // 1024} MiB")
    assert len(replies) == 2 and all(r and "existence_error" in r for r in replies), replies
    # measured +481 MiB; a list of small integers takes 2.6 x more (README)
    assert (hwm - base) * 1024 < 768 * MIB, (base, hwm)
    too_big = _frame(b"x" * (32 * MIB + 1))
    c = _Conn(port, 5, timeout=60)
    c.sock.sendall(too_big[:4096])
    reply = c.read()
    c.close()
    assert reply and "too_large" in reply, reply
