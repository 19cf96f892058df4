"""A node that was quiet for longer than every idle timeout still serves (issue 8).

The platform's worker pools let surplus workers exit after an idle time. That wait used to
*fail* on timeout (thread_get_message/3 fails when its timeout expires), ending the worker while
the pool still counted it as idle; jobs handed to it later reached nobody: connections got no
answer and arriving agents were never started. These tests shorten every idle timeout (the flag
``dfrl_pool_idle`` and the node's ``idle_timeout``), keep the node quiet past them, then send it
connections and agents.
"""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest

from dfrl.platform_pl import PLATFORM_DIR

from .conftest import SWIPL, Proc
from .wire_client import connect, connect_auth, frame, read_frame

pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")

TARTARUS = repr(str(PLATFORM_DIR / "tartarus.pl"))
POOL_IDLE_S = 0.3
CONN_IDLE_S = 0.5
QUIET_S = 2.0


def _swipl(procs: list[Proc], tmp_path: Path, name: str, program: str) -> Proc:
    path = tmp_path / f"{name}.pl"
    path.write_text(program)
    proc = Proc([SWIPL, "-q", "-g", "main", str(path)])
    procs.append(proc)
    return proc


def _quiet_node(procs: list[Proc], tmp_path: Path) -> tuple[Proc, int]:
    node = _swipl(
        procs,
        tmp_path,
        "quiet_node",
        f"""
    :- use_module({TARTARUS}).
    main :-
        set_prolog_flag(dfrl_pool_idle, {POOL_IDLE_S}),
        node_start(localhost:0, N, [token(55), idle_timeout({CONN_IDLE_S}), default(true)]),
        node_property(N, address(_:P)),
        format("LISTENING ~w~n", [P]), flush_output,
        thread_get_message(_).
    """,
    )
    return node, int(node.wait_for("LISTENING").split()[1])


def _agents_request(port: int, timeout: float = 5.0) -> bool:
    """One authenticated connection, one request; True when the node answered it."""
    try:
        with connect_auth(port, "55", timeout=timeout) as s:
            s.sendall(frame(b"agents .\n"))
            reply = read_frame(s)
            return reply is not None and reply[1].startswith("ok(")
    except (OSError, AssertionError):
        return False


def test_connections_answered_after_quiet(tmp_path: Path, procs: list[Proc]) -> None:
    # Prepare: a burst of 40 concurrent connections creates 40 connection workers.
    _, port = _quiet_node(procs, tmp_path)
    held = [connect(port) for _ in range(40)]
    time.sleep(0.2)
    for s in held:
        s.close()
    # Execute: quiet for longer than the pool's and the connections' idle timeouts,
    # then 50 connections, 10 at a time.
    time.sleep(QUIET_S)
    answered: list[bool] = []
    lock = threading.Lock()

    def one() -> None:
        ok = _agents_request(port)
        with lock:
            answered.append(ok)

    for _ in range(5):
        threads = [threading.Thread(target=one) for _ in range(10)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(timeout=15)
    # Assert
    assert len(answered) == 50 and all(answered), f"{answered.count(False)} of 50 unanswered"


def test_agents_start_after_quiet(tmp_path: Path, procs: list[Proc]) -> None:
    # Prepare: the quiet node, and a sender that moves one agent to it per line it reads.
    node, port = _quiet_node(procs, tmp_path)
    sender = _swipl(
        procs,
        tmp_path,
        "sender",
        f"""
    :- use_module({TARTARUS}).
    :- dynamic visitor/3.
    visitor(guid, (_, Port), main) :-          % runs at the quiet node (weak migration)
        format("ARRIVED ~w at ~w~n", [guid, Port]), flush_output.
    main :-
        node_start(localhost:0, _, [token(55), default(true)]),
        format("READY~n"), flush_output,
        between(1, 3, I),
            read_term(user_input, go, []),
            atom_concat(v, I, Name),
            create_mobile_agent(Name, visitor, [55]),
            move_agent(Name, (localhost, {port})),
            format("SENT ~w~n", [Name]), flush_output,
            I =:= 3, !,
        thread_get_message(_).
    """,
    )
    sender.wait_for("READY")
    # Execute and assert: each agent, sent after a quiet period, starts at the node.
    for i in (1, 2, 3):
        time.sleep(QUIET_S)
        assert sender.popen.stdin is not None
        sender.popen.stdin.write("go.\n")
        sender.popen.stdin.flush()
        sender.wait_for(f"SENT v{i}", timeout=15)
        node.wait_for(f"ARRIVED v{i}", timeout=15)
