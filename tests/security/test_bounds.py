"""Bounds on what an agent may take (issue 16, "a hostile peer gets nothing"), real processes.

A peer that holds the node's token sends agents that loop, build huge terms, clone themselves,
assert facts without end, flood the log and post without end. Each is stopped (or refused) by a
bound of ``platform_pl/agent_bounds.pl``, the node's CPU, memory and threads stay bounded
(read from ``/proc/PID``), the sender is told why (``agent_bound_report/3`` on its node), and an
ordinary agent from the same peer is accepted and runs afterwards. Each test has a control
that would fail if the bound were too tight: the same kind of work within the bound completes.
"""

from __future__ import annotations

import re
import time
from pathlib import Path

import pytest

from tests.platform.conftest import SWIPL, Proc
from tests.security.bounds_helpers import (
    MIB,
    ThreadSampler,
    attacker,
    cpu_seconds,
    start_victim,
    status,
)

pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")


def test_looping_agent_stopped_within_its_cpu_bound(tmp_path: Path, procs: list[Proc]) -> None:
    victim, port = start_victim(procs, tmp_path)  # agent_cpu_limit default: 2 s
    pid = victim.popen.pid
    time.sleep(0.5)
    c0 = cpu_seconds(pid)
    a = attacker(
        procs,
        tmp_path,
        """
    :- dynamic looper/3, burner/3.
    looper(guid, _, main) :- repeat, fail.
    burner(guid, _, main) :-
        statistics(cputime, T0),
        repeat, statistics(cputime, T), T - T0 >= 1.5, !,
        format("BURNED~n"), flush_output.
    """,
        f"""
        send(l1, looper, {port}), await_report(l1, 30),
        sleep(3),                                % the test measures the idle node meanwhile
        send(b1, burner, {port}), await_report(b1, 8),
        send(g1, good, {port}),
    """,
    )
    a.wait_for("REPORT l1", 40)
    c1 = cpu_seconds(pid)
    assert "REPORT l1 cpu(2)" in a.output(), a.output()
    # the node spent at most the bound plus 0.8 s (monitor period, transfer, notice) on it
    assert c1 - c0 < 2.8, (c1 - c0, victim.output())
    time.sleep(0.3)
    w0, t0 = cpu_seconds(pid), time.monotonic()
    time.sleep(1.5)
    idle = (cpu_seconds(pid) - w0) / (time.monotonic() - t0)
    print(f"loop: node CPU until stopped {c1 - c0:.2f} s, afterwards {idle:.1%} of a core")
    assert idle < 0.15  # dropped back
    assert "SENT b1" not in a.output()  # measured before it
    victim.wait_for("BURNED", 30)  # control: 1.5 s completes
    a.wait_for("DONE", 30)
    assert "NO REPORT b1" in a.output()
    victim.wait_for("GOOD at", 10)  # the same peer still served
    assert "agent l1 stopped and removed" in victim.output()
    assert "b1" not in victim.output().replace("BURNED", "")


def test_memory_bomb_stopped_and_rss_bounded(tmp_path: Path, procs: list[Proc]) -> None:
    victim, port = start_victim(procs, tmp_path)  # agent_stack_limit: 256 MiB
    pid = victim.popen.pid
    base = status(pid, "VmRSS")
    a = attacker(
        procs,
        tmp_path,
        """
    :- dynamic bomb/3, holder/3.
    bomb(guid, _, main) :- numlist(1, 200000000, L), length(L, N), N > 0.
    holder(guid, _, main) :- numlist(1, 1000000, L), sum_list(L, S),
                             format("HELD ~w~n", [S]), flush_output.
    """,
        f"""
        send(m1, bomb, {port}), await_report(m1, 30),
        send(h1, holder, {port}), await_report(h1, 3),
        send(g1, good, {port}),
    """,
    )
    a.wait_for("DONE", 60)
    assert "REPORT m1 memory(268435456)" in a.output(), a.output()
    hwm = status(pid, "VmHWM")
    print(f"memory bomb: RSS before {base // 1024} MiB, peak {hwm // 1024} MiB")
    # the bound (256 MiB of stacks) plus 160 MiB for the node, the transfer and GC slack;
    # without it one such agent takes about 920 MB
    assert (hwm - base) * 1024 < 416 * MIB, (base, hwm)
    victim.wait_for("HELD 500000500000", 10)  # control: a 1M list is fine
    assert "NO REPORT h1" in a.output()
    victim.wait_for("GOOD at", 10)


def test_clone_bomb_leaves_node_serving(tmp_path: Path, procs: list[Proc]) -> None:
    victim, port = start_victim(procs, tmp_path)  # max_agents 100, clone_limit 60/min
    pid = victim.popen.pid
    sampler = ThreadSampler(pid)
    a = attacker(
        procs,
        tmp_path,
        f"""
    :- dynamic cloner/3, pair/3.
    accept_loop(T0, N) :-                 % an ordinary agent every 0.5 s until one is accepted
        format(atom(G), 'g~d', [N]), create_mobile_agent(G, good, [5]),
        (   catch(move_agent(G, (localhost, {port})), E, (print_message(warning, E), fail))
        ->  get_time(T1), D is T1 - T0, format("ACCEPTED after ~3f s~n", [D])
        ;   N > 0
        ->  sleep(0.5), N1 is N - 1, accept_loop(T0, N1)
        ;   format("NEVER ACCEPTED~n")
        ).
    cloner(guid, Link, main) :- clone_agent(guid, Link, _), clone_agent(guid, Link, _).
    pair(guid, Link, main) :-             % a clone (named p1_N) only says that it runs
        (   sub_atom(guid, _, _, _, '_')
        ->  format("CLONE RUNS~n"), flush_output
        ;   clone_agent(guid, Link, C1), clone_agent(guid, Link, C2),
            format("PAIR ~w ~w~n", [C1, C2]), flush_output
        ).
    """,
        f"""
        create_mobile_agent(p1, pair, [5]), report(move_agent(p1, (localhost, {port}))),
        sleep(1),
        get_time(T0), send(c1, cloner, {port}),
        accept_loop(T0, 40),
        sleep(5),
        create_mobile_agent(g0, good, [5]), report(clone_agent(g0, (localhost, {port}), _)),
    """,
    )
    a.wait_for("DONE", 40)
    threads = sampler.stop()
    out = a.output()
    results = [line for line in out.splitlines() if line.startswith("RESULT")]
    assert results[:2] == ["RESULT ok", "RESULT ok"], out
    assert "clones" in results[2], out  # the sender of a refused clone is told why
    victim.wait_for("GOOD at", 20)
    assert "PAIR" in victim.output()  # control: a pair of clones is accepted
    m = re.search(r"ACCEPTED after ([\d.]+) s", out)
    assert m and float(m.group(1)) < 20, out
    # unbounded (clone_limit(infinite), max_agents(infinite)): 177 threads within 15 s;
    # bounded: about 65 (60 clones a minute, idle pool workers stay 30 s)
    print(f"clone bomb: at most {threads} threads, ordinary agent accepted after {m.group(1)} s")
    assert threads < 120, threads
    assert "clone_limit" in victim.output()
    assert len(victim.lines) < 80, victim.output()  # warnings are rate-limited


def test_assert_bomb_stopped(tmp_path: Path, procs: list[Proc]) -> None:
    # a generous CPU bound, so that the module bound is the one that stops it
    victim, port = start_victim(procs, tmp_path, "agent_cpu_limit(30)")
    pid = victim.popen.pid
    base = status(pid, "VmRSS")
    a = attacker(
        procs,
        tmp_path,
        """
    :- dynamic asserter/3, keeper/3.
    asserter(guid, _, main) :- between(1, inf, I), assertz(fact(I)), fail.
    keeper(guid, _, main) :- forall(between(1, 10000, I), assertz(kept(I))),
                             format("KEPT 10000~n"), flush_output.
    """,
        f"""
        get_time(T0), send(s1, asserter, {port}), await_report(s1, 30),
        get_time(T1), D is T1 - T0, format("STOPPED after ~3f s~n", [D]),
        send(k1, keeper, {port}), await_report(k1, 3),
        send(g1, good, {port}),
    """,
    )
    a.wait_for("DONE", 60)
    assert "REPORT s1 module_memory(67108864)" in a.output(), a.output()
    print(
        f"assert bomb: {a.wait_for('STOPPED after')}, RSS peak - before "
        f"{(status(pid, 'VmHWM') - base) // 1024} MiB"
    )
    assert (status(pid, "VmHWM") - base) * 1024 < 400 * MIB
    victim.wait_for("KEPT 10000", 10)  # control
    assert "NO REPORT k1" in a.output()
    victim.wait_for("GOOD at", 10)


def test_log_flood_cut(tmp_path: Path, procs: list[Proc]) -> None:
    victim, port = start_victim(procs, tmp_path)  # agent_log_limit: 200/min
    a = attacker(
        procs,
        tmp_path,
        """
    :- dynamic flood/3, talker/3.
    flood(guid, _, main) :- repeat, format("flood~n"), fail.
    talker(guid, _, main) :- forall(between(1, 50, I), format("talk ~w~n", [I])),
                             flush_output.
    """,
        f"""
        send(t1, talker, {port}), await_report(t1, 2),
        send(f1, flood, {port}), await_report(f1, 30),
        send(g1, good, {port}),
    """,
    )
    a.wait_for("DONE", 60)
    assert "REPORT f1 log(200)" in a.output(), a.output()
    victim.wait_for("GOOD at", 10)
    floods = [line for line in victim.lines if line == "flood"]
    assert 0 < len(floods) <= 200, len(floods)
    assert "talk 50" in victim.lines and "NO REPORT t1" in a.output()  # control
    assert sum("f1" in line for line in victim.lines) == 1, victim.output()  # one warning


def test_post_flood_cut(tmp_path: Path, procs: list[Proc]) -> None:
    victim, port = start_victim(procs, tmp_path, "agent_post_limit(50)")
    a = attacker(
        procs,
        tmp_path,
        """
    :- dynamic poster/3, few/3.
    poster(guid, Link, main) :- repeat, post_agent(platform, Link, [poster, guid, Link, ping]), fail.
    poster(guid, _, ping).
    few(guid, Link, main) :- forall(between(1, 20, _), post_agent(platform, Link, [few, guid, Link, ping])),
                             format("POSTED 20~n"), flush_output.
    few(guid, _, ping).
    """,
        f"""
        send(q1, few, {port}), await_report(q1, 2),
        send(p1, poster, {port}), await_report(p1, 30),
        send(g1, good, {port}),
    """,
    )
    a.wait_for("DONE", 60)
    assert "REPORT p1 posts(50)" in a.output(), a.output()
    victim.wait_for("POSTED 20", 10)  # control
    assert "NO REPORT q1" in a.output()
    victim.wait_for("GOOD at", 10)
    assert status(victim.popen.pid, "Threads") < 80
