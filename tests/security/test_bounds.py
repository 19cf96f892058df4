"""Bounds on what an agent may take (issue 16, "a hostile peer gets nothing"), real processes.

A peer that holds the node's token sends agents that loop, build huge terms, clone themselves,
assert facts without end, flood the log and post without end. Each is stopped (or refused) by a
bound of ``platform_pl/agent_bounds.pl``, the node's CPU, memory and threads stay bounded
(read from ``/proc/PID``), the sender is told why (``agent_bound_report/3`` on its node), and an
ordinary agent from the same peer is accepted and runs afterwards. Each test has a control
that would fail if the bound were too tight: the same kind of work within the bound completes.
"""
from __future__ import annotations

import os
import re
import threading
import time
from pathlib import Path

import pytest

from dfrl.platform_pl import PLATFORM_DIR

from tests.platform.conftest import SWIPL, Proc

pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")

TICK = os.sysconf("SC_CLK_TCK")
MIB = 1024 * 1024


def start_victim(procs: list[Proc], tmp_path: Path, options: str = "") -> tuple[Proc, int]:
    """A node with token 5 and the given extra node options; return it and its port."""
    path = tmp_path / f"victim_{len(procs)}.pl"
    path.write_text(f"""
    :- use_module({str(PLATFORM_DIR / 'tartarus.pl')!r}).
    main :- node_start(localhost:0, N, [token(5), default(true){', ' + options if options else ''}]),
            node_property(N, address(H:P)),
            format("dfrl node listening on ~w:~w~n", [H, P]), flush_output,
            thread_get_message(_).
    """)
    assert SWIPL
    p = Proc([SWIPL, "-q", "-g", "main", str(path)])
    procs.append(p)
    line = p.wait_for("listening on")
    return p, int(line.rsplit(":", 1)[1])


def attacker(procs: list[Proc], tmp_path: Path, clauses: str, body: str) -> Proc:
    """A process with its own node (token 5) that runs ``body``; its agents are ``clauses``.

    ``await_report(Name, Secs)`` prints ``REPORT Name Kind`` once the victim told this node
    that its agent Name was stopped, or ``NO REPORT Name`` after Secs.
    """
    prog = f"""
    :- use_module({str(PLATFORM_DIR / 'tartarus.pl')!r}).
    :- use_module({str(PLATFORM_DIR / 'agent_bounds.pl')!r}).
    :- dynamic good/3.
    good(guid, (_, P), main) :- format("GOOD at ~w~n", [P]), flush_output.
    {clauses}
    report(Goal) :-
        catch((Goal, T = ok), E, message_to_codes(E, T)),
        format("RESULT ~w~n", [T]), flush_output.
    message_to_codes(E, T) :-
        '$messages':translate_message(E, L, []),
        with_output_to(string(T), print_message_lines(current_output, '', L)).
    send(Name, Handler, Port) :-
        create_mobile_agent(Name, Handler, [5]),
        report(move_agent(Name, (localhost, Port))),
        format("SENT ~w~n", [Name]), flush_output.
    await_report(Name, Secs) :-
        current_node(Here), get_time(T0), Deadline is T0 + Secs,
        await_loop(Here, Name, Deadline).
    await_loop(Here, Name, Deadline) :-
        (   agent_bound_report(Here, Name, bound(Kind, _, _, _))
        ->  format("REPORT ~w ~q~n", [Name, Kind])
        ;   get_time(Now), Now < Deadline
        ->  sleep(0.05), await_loop(Here, Name, Deadline)
        ;   format("NO REPORT ~w~n", [Name])
        ),
        flush_output.
    main :- node_start(localhost:0, _, [token(5)]),
            {body}
            format("DONE~n"), flush_output.
    """
    path = tmp_path / f"attacker_{len(procs)}.pl"
    path.write_text(prog)
    assert SWIPL
    proc = Proc([SWIPL, "-q", "-g", "main", "-t", "halt", str(path)])
    procs.append(proc)
    return proc


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of process ``pid`` so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICK


def status(pid: int, key: str) -> int:
    """A numeric field of ``/proc/PID/status`` (kB for memory fields)."""
    m = re.search(rf"^{key}:\s+(\d+)", Path(f"/proc/{pid}/status").read_text(), re.M)
    assert m, key
    return int(m.group(1))


class ThreadSampler:
    """Samples the thread count of a process every 0.1 s (for at most ``limit_s``)."""

    def __init__(self, pid: int, limit_s: float = 60.0) -> None:
        self.pid, self.limit_s, self.counts = pid, limit_s, []
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, daemon=True)
        self._t.start()

    def _run(self) -> None:
        end = time.monotonic() + self.limit_s
        while not self._stop.is_set() and time.monotonic() < end:
            try:
                self.counts.append(status(self.pid, "Threads"))
            except (OSError, AssertionError):
                return
            self._stop.wait(0.1)

    def stop(self) -> int:
        self._stop.set()
        self._t.join(5)
        return max(self.counts)


def test_looping_agent_stopped_within_its_cpu_bound(tmp_path: Path, procs: list[Proc]) -> None:
    victim, port = start_victim(procs, tmp_path)                 # agent_cpu_limit default: 2 s
    pid = victim.popen.pid
    time.sleep(0.5)
    c0 = cpu_seconds(pid)
    a = attacker(procs, tmp_path, """
    :- dynamic looper/3, burner/3.
    looper(guid, _, main) :- repeat, fail.
    burner(guid, _, main) :-
        statistics(cputime, T0),
        repeat, statistics(cputime, T), T - T0 >= 1.5, !,
        format("BURNED~n"), flush_output.
    """, f"""
        send(l1, looper, {port}), await_report(l1, 30),
        sleep(3),                                % the test measures the idle node meanwhile
        send(b1, burner, {port}), await_report(b1, 8),
        send(g1, good, {port}),
    """)
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
    assert idle < 0.15                                              # dropped back
    assert "SENT b1" not in a.output()                              # measured before it
    victim.wait_for("BURNED", 30)                                  # control: 1.5 s completes
    a.wait_for("DONE", 30)
    assert "NO REPORT b1" in a.output()
    victim.wait_for("GOOD at", 10)                                 # the same peer still served
    assert "agent l1 stopped and removed" in victim.output()
    assert "b1" not in victim.output().replace("BURNED", "")


def test_memory_bomb_stopped_and_rss_bounded(tmp_path: Path, procs: list[Proc]) -> None:
    victim, port = start_victim(procs, tmp_path)                 # agent_stack_limit: 256 MiB
    pid = victim.popen.pid
    base = status(pid, "VmRSS")
    a = attacker(procs, tmp_path, """
    :- dynamic bomb/3, holder/3.
    bomb(guid, _, main) :- numlist(1, 200000000, L), length(L, N), N > 0.
    holder(guid, _, main) :- numlist(1, 1000000, L), sum_list(L, S),
                             format("HELD ~w~n", [S]), flush_output.
    """, f"""
        send(m1, bomb, {port}), await_report(m1, 30),
        send(h1, holder, {port}), await_report(h1, 3),
        send(g1, good, {port}),
    """)
    a.wait_for("DONE", 60)
    assert "REPORT m1 memory(268435456)" in a.output(), a.output()
    hwm = status(pid, "VmHWM")
    print(f"memory bomb: RSS before {base // 1024} MiB, peak {hwm // 1024} MiB")
    # the bound (256 MiB of stacks) plus 160 MiB for the node, the transfer and GC slack;
    # without it one such agent takes about 920 MB
    assert (hwm - base) * 1024 < 416 * MIB, (base, hwm)
    victim.wait_for("HELD 500000500000", 10)                       # control: a 1M list is fine
    assert "NO REPORT h1" in a.output()
    victim.wait_for("GOOD at", 10)


def test_clone_bomb_leaves_node_serving(tmp_path: Path, procs: list[Proc]) -> None:
    victim, port = start_victim(procs, tmp_path)          # max_agents 100, clone_limit 60/min
    pid = victim.popen.pid
    sampler = ThreadSampler(pid)
    a = attacker(procs, tmp_path, f"""
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
    """, f"""
        create_mobile_agent(p1, pair, [5]), report(move_agent(p1, (localhost, {port}))),
        sleep(1),
        get_time(T0), send(c1, cloner, {port}),
        accept_loop(T0, 40),
        sleep(5),
        create_mobile_agent(g0, good, [5]), report(clone_agent(g0, (localhost, {port}), _)),
    """)
    a.wait_for("DONE", 40)
    threads = sampler.stop()
    out = a.output()
    results = [line for line in out.splitlines() if line.startswith("RESULT")]
    assert results[:2] == ["RESULT ok", "RESULT ok"], out
    assert "clones" in results[2], out             # the sender of a refused clone is told why
    victim.wait_for("GOOD at", 20)
    assert "PAIR" in victim.output()               # control: a pair of clones is accepted
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
    a = attacker(procs, tmp_path, """
    :- dynamic asserter/3, keeper/3.
    asserter(guid, _, main) :- between(1, inf, I), assertz(fact(I)), fail.
    keeper(guid, _, main) :- forall(between(1, 10000, I), assertz(kept(I))),
                             format("KEPT 10000~n"), flush_output.
    """, f"""
        get_time(T0), send(s1, asserter, {port}), await_report(s1, 30),
        get_time(T1), D is T1 - T0, format("STOPPED after ~3f s~n", [D]),
        send(k1, keeper, {port}), await_report(k1, 3),
        send(g1, good, {port}),
    """)
    a.wait_for("DONE", 60)
    assert "REPORT s1 module_memory(67108864)" in a.output(), a.output()
    print(f"assert bomb: {a.wait_for('STOPPED after')}, RSS peak - before "
          f"{(status(pid, 'VmHWM') - base) // 1024} MiB")
    assert (status(pid, "VmHWM") - base) * 1024 < 400 * MIB
    victim.wait_for("KEPT 10000", 10)                               # control
    assert "NO REPORT k1" in a.output()
    victim.wait_for("GOOD at", 10)


def test_log_flood_cut(tmp_path: Path, procs: list[Proc]) -> None:
    victim, port = start_victim(procs, tmp_path)                   # agent_log_limit: 200/min
    a = attacker(procs, tmp_path, """
    :- dynamic flood/3, talker/3.
    flood(guid, _, main) :- repeat, format("flood~n"), fail.
    talker(guid, _, main) :- forall(between(1, 50, I), format("talk ~w~n", [I])),
                             flush_output.
    """, f"""
        send(t1, talker, {port}), await_report(t1, 2),
        send(f1, flood, {port}), await_report(f1, 30),
        send(g1, good, {port}),
    """)
    a.wait_for("DONE", 60)
    assert "REPORT f1 log(200)" in a.output(), a.output()
    victim.wait_for("GOOD at", 10)
    floods = [line for line in victim.lines if line == "flood"]
    assert 0 < len(floods) <= 200, len(floods)
    assert "talk 50" in victim.lines and "NO REPORT t1" in a.output()   # control
    assert sum("f1" in line for line in victim.lines) == 1, victim.output()  # one warning


def test_post_flood_cut(tmp_path: Path, procs: list[Proc]) -> None:
    victim, port = start_victim(procs, tmp_path, "agent_post_limit(50)")
    a = attacker(procs, tmp_path, """
    :- dynamic poster/3, few/3.
    poster(guid, Link, main) :- repeat, post_agent(platform, Link, [poster, guid, Link, ping]), fail.
    poster(guid, _, ping).
    few(guid, Link, main) :- forall(between(1, 20, _), post_agent(platform, Link, [few, guid, Link, ping])),
                             format("POSTED 20~n"), flush_output.
    few(guid, _, ping).
    """, f"""
        send(q1, few, {port}), await_report(q1, 2),
        send(p1, poster, {port}), await_report(p1, 30),
        send(g1, good, {port}),
    """)
    a.wait_for("DONE", 60)
    assert "REPORT p1 posts(50)" in a.output(), a.output()
    victim.wait_for("POSTED 20", 10)                                  # control
    assert "NO REPORT q1" in a.output()
    victim.wait_for("GOOD at", 10)
    assert status(victim.popen.pid, "Threads") < 80


def wait_rss_settled(pid: int, base_kb: int, within_kb: int, limit_s: float = 10.0) -> int:
    """VmRSS of ``pid`` (kB) once it is within ``within_kb`` of ``base_kb``, or after
    ``limit_s`` seconds."""
    end = time.monotonic() + limit_s
    rss = status(pid, "VmRSS")
    while rss - base_kb > within_kb and time.monotonic() < end:
        time.sleep(0.2)
        rss = status(pid, "VmRSS")
    return rss


def concurrent_bombs(procs: list[Proc], tmp_path: Path, port: int, handler: str,
                     clauses: str, n: int = 8) -> Proc:
    """An attacker that sends ``n`` agents with ``handler`` at once (b1..bn), waits for the
    victim's report on each, then sends an ordinary agent g1."""
    names = [f"b{i}" for i in range(1, n + 1)]
    sends = "".join(f"send({b}, {handler}, {port}), " for b in names)
    awaits = "".join(f"await_report({b}, 40), " for b in names)
    return attacker(procs, tmp_path, clauses, f"""
        get_time(T0), {sends}
        {awaits}
        get_time(T1), D is T1 - T0, format("ALL STOPPED after ~3f s~n", [D]),
        send(g1, good, {port}),
    """)


def test_eight_memory_bombs_within_node_budget(tmp_path: Path, procs: list[Proc]) -> None:
    # defaults: agent_stack_limit 256 MiB, agent_memory_budget 1 GiB, max_running_agents 8
    victim, port = start_victim(procs, tmp_path)
    pid = victim.popen.pid
    time.sleep(0.3)
    base = status(pid, "VmRSS")
    a = concurrent_bombs(procs, tmp_path, port, "bomb", """
    :- dynamic bomb/3.
    bomb(guid, _, main) :- numlist(1, 200000000, L), length(L, N), N > 0.
    """)
    a.wait_for("DONE", 120)
    out = a.output()
    kinds = re.findall(r"REPORT b\d+ (\w+)\(", out)
    assert len(kinds) == 8 and set(kinds) <= {"memory", "memory_budget"}, out
    hwm = status(pid, "VmHWM")
    victim.wait_for("GOOD at", 20)
    after = wait_rss_settled(pid, base, 50 * 1024)
    print(f"8 memory bombs: {a.wait_for('ALL STOPPED')}, stopped by {sorted(kinds)}; RSS before "
          f"{base // 1024} MiB, peak +{(hwm - base) // 1024} MiB, after +{(after - base) // 1024} MiB")
    # the stated bound (README "Bounds on agents"), the hard one: stacks never exceed
    # max_running_agents x agent_stack_limit (8 x 256 MiB), plus 256 MiB for the node itself.
    # The budget (1 GiB, enforced by the monitor) keeps it lower when the monitor gets the CPU:
    # +443..+541 MiB on a quiet machine, +1720 MiB with stress-ng --cpu 2 beside it
    assert (hwm - base) * 1024 < 8 * 256 * MIB + 256 * MIB, (base, hwm)
    assert (after - base) < 50 * 1024, (base, after)


def test_eight_assert_bombs_within_node_budget(tmp_path: Path, procs: list[Proc]) -> None:
    victim, port = start_victim(procs, tmp_path, "agent_cpu_limit(30)")
    pid = victim.popen.pid
    time.sleep(0.3)
    base = status(pid, "VmRSS")
    a = concurrent_bombs(procs, tmp_path, port, "asserter", """
    :- dynamic asserter/3.
    asserter(guid, _, main) :- between(1, inf, I), assertz(fact(I)), fail.
    """)
    a.wait_for("DONE", 180)
    out = a.output()
    kinds = re.findall(r"REPORT b\d+ (\w+)\(", out)
    assert len(kinds) == 8 and set(kinds) <= {"module_memory", "memory_budget"}, out
    hwm = status(pid, "VmHWM")
    victim.wait_for("GOOD at", 20)
    after = wait_rss_settled(pid, base, 50 * 1024)
    print(f"8 assert bombs: {a.wait_for('ALL STOPPED')}, stopped by {sorted(kinds)}; RSS before "
          f"{base // 1024} MiB, peak +{(hwm - base) // 1024} MiB, after +{(after - base) // 1024} MiB")
    assert (hwm - base) * 1024 < 1024 * MIB + 512 * MIB, (base, hwm)
    assert (after - base) < 50 * 1024, (base, after)


def test_assert_bombs_stopped_by_node_budget(tmp_path: Path, procs: list[Proc]) -> None:
    # a budget below the sum of the module limits (8 x 64 MiB): the budget stops them
    victim, port = start_victim(procs, tmp_path,
                                "agent_cpu_limit(30), agent_memory_budget(268435456)")
    pid = victim.popen.pid
    time.sleep(0.3)
    base = status(pid, "VmRSS")
    a = concurrent_bombs(procs, tmp_path, port, "asserter", """
    :- dynamic asserter/3.
    asserter(guid, _, main) :- between(1, inf, I), assertz(fact(I)), fail.
    """)
    a.wait_for("DONE", 180)
    kinds = re.findall(r"REPORT b\d+ (\w+)\(", a.output())
    assert len(kinds) == 8 and "memory_budget" in kinds, a.output()
    hwm = status(pid, "VmHWM")
    victim.wait_for("GOOD at", 20)
    print(f"8 assert bombs, budget 256 MiB: stopped by {sorted(kinds)}; "
          f"RSS peak +{(hwm - base) // 1024} MiB")
    # facts take about 1.15 x their predicate_property size in RSS, and the calls grow until
    # the monitor's next tick, which comes late on a loaded machine (+559 MiB was seen while
    # the whole suite ran): the stated bound is the budget plus 8 slots x 64 MiB
    assert (hwm - base) * 1024 < 256 * MIB + 512 * MIB, (base, hwm)


def test_running_slots_bound_stacks(tmp_path: Path, procs: list[Proc]) -> None:
    # no budget: only max_running_agents(2) x agent_stack_limit(128 MiB) bounds the stacks
    victim, port = start_victim(procs, tmp_path,
                                "agent_memory_budget(infinite), max_running_agents(2), "
                                "agent_stack_limit(134217728)")
    pid = victim.popen.pid
    time.sleep(0.3)
    base = status(pid, "VmRSS")
    a = concurrent_bombs(procs, tmp_path, port, "bomb", """
    :- dynamic bomb/3.
    bomb(guid, _, main) :- numlist(1, 200000000, L), length(L, N), N > 0.
    """)
    a.wait_for("DONE", 180)
    kinds = re.findall(r"REPORT b\d+ (\w+)\(", a.output())
    assert kinds == ["memory"] * 8, a.output()
    hwm = status(pid, "VmHWM")
    victim.wait_for("GOOD at", 20)
    print(f"8 memory bombs, 2 slots of 128 MiB: {a.wait_for('ALL STOPPED')}; "
          f"RSS peak +{(hwm - base) // 1024} MiB")
    assert (hwm - base) * 1024 < 2 * 128 * MIB + 128 * MIB, (base, hwm)


def test_two_max_size_frames_bounded(tmp_path: Path, procs: list[Proc]) -> None:
    from dfrl.experiments.tools.bench.hostile_auth_attacks import _Conn, _frame

    victim, port = start_victim(procs, tmp_path)               # max_frame_size: 32 MiB
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
