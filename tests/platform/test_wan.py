"""Pooled connections across long rests, their cost over a delayed link, and no fd leaks (issue 8).

A hop on a pooled connection costs the transfer (one round trip to the staged answer) and the
commit (half a round trip): 1.5 RTT. A new connection adds the hello (0.5 RTT) and the token
proof (1 RTT). Connections used to be dropped from the pool after 5 s and closed by the server
after 10 s of silence, so every hop after a long rest paid for a new connection; and a pooled
connection to a peer that was never visited again stayed open for ever (CLOSE_WAIT). Here a
Python proxy delays every chunk by 50 ms each way between two node processes.
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest

from dfrl.experiments.tools.bench.fault_proxy import FaultProxy
from dfrl.platform_pl import PLATFORM_DIR

from .conftest import SWIPL, Proc

pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")

TARTARUS = repr(str(PLATFORM_DIR / "tartarus.pl"))
ONE_WAY_S = 0.05
RTT_S = 2 * ONE_WAY_S


def _swipl(procs: list[Proc], tmp_path: Path, name: str, program: str) -> Proc:
    path = tmp_path / f"{name}.pl"
    path.write_text(program)
    proc = Proc([SWIPL, "-q", "-g", "main", str(path)])
    procs.append(proc)
    return proc


def _destination(
    procs: list[Proc], tmp_path: Path, options: str = "", nodes: int = 1, name: str = "dest"
) -> tuple[Proc, list[int]]:
    """A process with ``nodes`` nodes (token 7); returns it and their ports."""
    proc = _swipl(
        procs,
        tmp_path,
        name,
        f"""
    :- use_module({TARTARUS}).
    main :-
        forall(between(1, {nodes}, _),
               ( node_start('127.0.0.1':0, N, [token(7){options}]),
                 node_property(N, address(_:P)),
                 format("LISTENING ~w~n", [P]) )),
        flush_output,
        thread_get_message(_).
    """,
    )
    proc.wait_for("LISTENING")
    deadline = time.monotonic() + 20
    while time.monotonic() < deadline:
        ports = [int(line.split()[1]) for line in list(proc.lines) if line.startswith("LISTENING")]
        if len(ports) == nodes:
            return proc, ports
        time.sleep(0.02)
    raise AssertionError(f"{nodes} nodes did not start:\n{proc.output()}")


def _source(procs: list[Proc], tmp_path: Path, flags: str = "") -> Proc:
    """A process that, for each `move(Name, Port).` on stdin, creates agent Name and moves it.

    The agent prints ``ARRIVED Name Time`` where it arrives; the source prints ``SENT Name
    Time`` just before the move and ``MOVED Name`` or ``FAILED Name`` after it.
    """
    proc = _swipl(
        procs,
        tmp_path,
        "source",
        f"""
    :- use_module({TARTARUS}).
    :- dynamic hop/3.
    hop(guid, _, main) :-
        get_time(T), format("ARRIVED ~w ~6f~n", [guid, T]), flush_output.
    main :-
        {flags}
        node_start('127.0.0.1':0, _, [token(7), default(true)]),
        format("READY~n"), flush_output,
        repeat,
        read_term(user_input, Cmd, []),
        (   Cmd == end_of_file
        ->  !
        ;   Cmd = move(Name, Port),
            create_mobile_agent(Name, hop, [7]),
            get_time(T0), format("SENT ~w ~6f~n", [Name, T0]), flush_output,
            (   catch(move_agent(Name, ('127.0.0.1', Port)), E, true)
            ->  true
            ;   E = failed
            ),
            (   var(E)
            ->  format("MOVED ~w~n", [Name])
            ;   purge_agent(Name),
                format("FAILED ~w ~q~n", [Name, E])
            ),
            flush_output,
            fail
        ).
    """,
    )
    proc.wait_for("READY")
    return proc


def _move(source: Proc, dest: Proc, name: str, port: int) -> float:
    """Move a new agent; seconds from the call of move_agent to its start at the destination."""
    assert source.popen.stdin is not None
    source.popen.stdin.write(f"move({name}, {port}).\n")
    source.popen.stdin.flush()
    sent = float(source.wait_for(f"SENT {name} ").split()[2])
    arrived = float(dest.wait_for(f"ARRIVED {name} ").split()[2])
    source.wait_for(f"MOVED {name}")
    return arrived - sent


def test_pooled_hop_after_long_rest_costs_one_and_a_half_rtt(
    tmp_path: Path, procs: list[Proc]
) -> None:
    # Prepare: source -> proxy (50 ms each way) -> destination, default timeouts.
    dest, [port] = _destination(procs, tmp_path)
    with FaultProxy(("127.0.0.1", port), delay_s=ONE_WAY_S) as proxy:
        source = _source(procs, tmp_path)
        # Execute: a first move (new connection), a 12 s rest (longer than the old pool
        # window of 5 s and the old server idle timeout of 10 s), a second move.
        first = _move(source, dest, "a1", proxy.address[1])
        time.sleep(12.0)
        pooled = _move(source, dest, "a2", proxy.address[1])
        print(
            f"\nhop over 50 ms one-way: new connection {first * 1000:.0f} ms, "
            f"pooled after 12 s rest {pooled * 1000:.0f} ms (RTT {RTT_S * 1000:.0f} ms)"
        )
        # Assert: one connection served both moves; the pooled one costs 1.5 RTT where a new
        # connection costs 2.5 or more: under 2 RTT, and at least half an RTT less than the new
        # one (a busy machine adds to both; 1.5 RTT + 30 ms failed at 180 ms once, load 6).
        assert proxy.connections == 1
        assert first >= 2.5 * RTT_S
        assert pooled < 2.0 * RTT_S and first - pooled > 0.5 * RTT_S, (first, pooled)


def test_keepalive_outlives_the_servers_idle_timeout(tmp_path: Path, procs: list[Proc]) -> None:
    # Prepare: the destination closes authenticated connections after 1.5 s of silence; the
    # source pings its pooled connections after 0.3 s of silence. (A hop that meets its
    # connection out for a ping waits for the pong: at most one RTT more.)
    dest, [port] = _destination(procs, tmp_path, ", auth_idle_timeout(1.5)")
    with FaultProxy(("127.0.0.1", port), delay_s=ONE_WAY_S) as proxy:
        source = _source(procs, tmp_path, "set_prolog_flag(dfrl_keepalive, 0.3),")
        _move(source, dest, "k1", proxy.address[1])
        # Execute: rest for more than twice the server's limit.
        time.sleep(4.0)
        pooled = _move(source, dest, "k2", proxy.address[1])
        # Assert
        assert proxy.connections == 1
        assert pooled < 2.5 * RTT_S + 0.030


def _sockets(pid: int) -> int:
    n = 0
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            if os.readlink(f"/proc/{pid}/fd/{fd}").startswith("socket:"):
                n += 1
        except OSError:
            pass
    return n


def test_connections_to_peers_that_left_are_closed(tmp_path: Path, procs: list[Proc]) -> None:
    # Prepare: a source; ten generations of five peers each, every generation killed (-9)
    # after the source has moved an agent to each of its peers: 50 moves, 50 peers.
    source = _source(procs, tmp_path)
    pid = source.popen.pid
    baseline = _sockets(pid)
    counts = []
    # Execute
    for gen in range(10):
        dest, ports = _destination(procs, tmp_path, nodes=5, name=f"peers{gen}")
        for i, port in enumerate(ports):
            _move(source, dest, f"g{gen}_{i}", port)
        counts.append(_sockets(pid))
        os.kill(dest.popen.pid, signal.SIGKILL)
        dest.popen.wait(timeout=10)
    deadline = time.monotonic() + 5
    while _sockets(pid) > baseline and time.monotonic() < deadline:
        time.sleep(0.1)
    # Assert: at most the live generation's connections are open, and none once it is gone.
    assert max(counts) <= baseline + 5, counts
    assert _sockets(pid) == baseline, (baseline, _sockets(pid))
