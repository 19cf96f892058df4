"""Limits before authentication, tried as an attacker would (issue 9): real processes, sockets.

A whole-frame deadline (a peer trickling bytes is cut off however slowly it sends), caps on
unauthenticated connections per peer and in total that never displace authenticated ones,
a term depth limit with a parse cost linear in the frame, memory given back after large
rejected frames, binary frames bounded by the frame size limit.
"""
from __future__ import annotations

import socket
import threading
import time
from pathlib import Path

from . import hostile_node
from .conftest import Proc
from .wire_client import connect, connect_auth, frame, read_frame

TOKEN = "9"


def _node(procs: list[Proc], tmp_path: Path, extra: str = "") -> tuple[Proc, int]:
    return hostile_node.start(procs, tmp_path, f"[token({TOKEN}){extra}]")


def _ping(s: socket.socket) -> str:
    s.sendall(frame(b"ping .\n"))
    reply = read_frame(s)
    assert reply is not None
    return reply[1]


def _closed_by_server(s: socket.socket, within: float) -> bool:
    """True if the server closes ``s`` (possibly after an error frame) within ``within`` s."""
    s.settimeout(within)
    try:
        while True:
            if not s.recv(4096):
                return True
    except (TimeoutError, socket.timeout):
        return False
    except OSError:
        return True


def test_trickled_frame_hits_the_whole_frame_deadline(tmp_path: Path, procs: list[Proc]) -> None:
    # Prepare: the deadline is 1 s per frame; the idle timeout per read stays 10 s.
    _, port = _node(procs, tmp_path, ", frame_deadline(1)")
    s = connect(port)
    data = frame(b"ping .\n")
    # Execute: one byte every 0.25 s (each read well within the idle timeout)
    t0 = time.monotonic()
    reply = None
    s.settimeout(0.05)
    for b in data:
        try:
            s.sendall(bytes([b]))
        except OSError:
            break
        try:
            got = s.recv(4096)
            reply = got
            break
        except (TimeoutError, socket.timeout):
            pass
        time.sleep(0.2)
    elapsed = time.monotonic() - t0
    # Assert: cut off after about the deadline, told why, long before the frame was complete
    assert reply is not None and b"deadline" in reply, reply
    assert elapsed < 2.5, elapsed
    s.close()


def test_unauthenticated_flood_never_displaces_authenticated(tmp_path: Path,
                                                            procs: list[Proc]) -> None:
    # Prepare: 16 connections at most, 8 unauthenticated, 4 per peer address.
    _, port = _node(procs, tmp_path,
                    ", max_connections(16), max_unauth_connections(8), max_unauth_per_peer(4)")
    held = connect_auth(port, TOKEN)
    # Execute: 40 idle unauthenticated connections from one address, 10 each from two others
    idle = [connect(port) for _ in range(40)]
    idle += [connect(port, source="127.0.0.2") for _ in range(10)]
    idle += [connect(port, source="127.0.0.3") for _ in range(10)]
    # Assert: the held authenticated connection still serves, a new one authenticates at once
    assert _ping(held).startswith("ok(pong(")
    t0 = time.monotonic()
    fresh = connect_auth(port, TOKEN)
    assert _ping(fresh).startswith("ok(pong(")
    assert time.monotonic() - t0 < 1.0
    # the oldest idle connections were evicted: at most 8 unauthenticated are still open
    open_now = sum(not _closed_by_server(s, 0.05) for s in idle)
    assert open_now <= 8, open_now
    for s in idle + [held, fresh]:
        s.close()


def test_operator_chain_costs_linear_time(tmp_path: Path, procs: list[Proc]) -> None:
    # Prepare: a 60 KB operator chain (under the 64 KiB pre-authentication limit) and a
    # 2 MB one after authentication (an unknown request: the node answers its name only).
    node, port = _node(procs, tmp_path)
    chain = b"a+" * 30000 + b"a .\n"
    big = b"a+" * 1000000 + b"a .\n"
    cpu0 = hostile_node.cpu_s(node.popen.pid)
    # Execute
    with connect(port) as s:
        s.sendall(frame(chain))
        before_auth = read_frame(s)
    with connect_auth(port, TOKEN, timeout=30) as s:
        s.sendall(frame(big))
        after_auth = read_frame(s)
    with connect(port) as s:
        s.sendall(frame(b"a+" * 100000 + b"a .\n"))
        oversized = read_frame(s)
    cpu = hostile_node.cpu_s(node.popen.pid) - cpu0
    # Assert: refused for its depth, answered by name, refused for its size; seconds, not hours
    assert before_auth is not None and "too_deep(64)" in before_auth[1], before_auth
    assert after_auth is not None and "domain_error(platform_request,/(+,2))" in after_auth[1], after_auth
    assert oversized is not None and "too_large(200004,65536)" in oversized[1], oversized
    assert cpu < 5.0, cpu


def test_memory_given_back_after_large_rejected_frames(tmp_path: Path, procs: list[Proc]) -> None:
    # Prepare: 8 authenticated peers each send an 8 MB text frame that fails to parse at its end.
    node, port = _node(procs, tmp_path)
    pid = node.popen.pid
    time.sleep(0.3)
    rss0 = hostile_node.rss_mb(pid)
    body = b"[" + b"1.5," * 2000000 + b" .\n"
    replies: list[str] = []
    lock = threading.Lock()

    def one() -> None:
        with connect_auth(port, TOKEN, timeout=60) as s:
            s.sendall(frame(body))
            r = read_frame(s)
            with lock:
                replies.append(r[1] if r else "closed")

    threads = [threading.Thread(target=one) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=120)
    time.sleep(1.0)
    rss1 = hostile_node.rss_mb(pid)
    # Assert: every frame rejected as a syntax error, and the memory is back within 50 MB
    assert len(replies) == 8 and all("syntax" in r for r in replies), replies
    assert rss1 - rss0 < 50, (rss0, rss1)


def test_binary_frames_bounded_by_the_frame_size(tmp_path: Path, procs: list[Proc]) -> None:
    _, port = _node(procs, tmp_path, ", max_frame_size(1000000)")
    with connect_auth(port, TOKEN) as s:
        s.sendall(frame(b"\0" * 16, kind=b"B", length=2000000))
        reply = read_frame(s)
        assert reply is not None and "too_large(2000000,1000000)" in reply[1], reply
    with connect(port) as s:
        s.sendall(frame(b"\0" * 16, kind=b"B"))
        reply = read_frame(s)
        assert reply is not None and "binary_not_allowed" in reply[1], reply


def test_pipelined_frames_before_authentication_are_refused(tmp_path: Path,
                                                            procs: list[Proc]) -> None:
    _, port = _node(procs, tmp_path)
    with connect(port) as s:
        s.sendall(frame(b"ping .\n") + frame(b"ping .\n"))
        reply = read_frame(s)
        assert reply is not None and "pipelined" in reply[1], reply
