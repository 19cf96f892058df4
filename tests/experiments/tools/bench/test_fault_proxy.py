"""The fault proxy with a real echo server and a real platform node (no mocks)."""

from __future__ import annotations

import socket
import struct
import subprocess
import threading
import time
from collections.abc import Iterator

import pytest

from dfrl.experiments.tools.bench.fault_proxy import DROP, PASS, STALL, FaultProxy
from dfrl.platform_pl import PLATFORM_DIR
from dfrl.experiments.processes import find_swipl

SWIPL = find_swipl()


def frame(body: bytes, kind: bytes = b"T") -> bytes:
    return b"DFRL" + bytes([1]) + kind + b"\0\0" + struct.pack(">I", len(body)) + body


def read_exact(s: socket.socket, n: int) -> bytes:
    out = b""
    while len(out) < n:
        chunk = s.recv(n - len(out))
        if not chunk:
            raise ConnectionError("closed")
        out += chunk
    return out


def read_frame(s: socket.socket) -> tuple[bytes, bytes]:
    header = read_exact(s, 12)
    assert header[:4] == b"DFRL"
    (length,) = struct.unpack(">I", header[8:12])
    return header[5:6], read_exact(s, length)


@pytest.fixture
def echo() -> Iterator[tuple[str, int]]:
    """A TCP echo server on loopback (one thread per connection, bounded by the test)."""
    server = socket.create_server(("127.0.0.1", 0))
    server.settimeout(0.2)
    stop = threading.Event()

    def serve(c: socket.socket) -> None:
        c.settimeout(0.2)
        with c:
            while not stop.is_set():
                try:
                    data = c.recv(65536)
                except socket.timeout:
                    continue
                except OSError:
                    return
                if not data:
                    return
                try:
                    c.sendall(data)
                except OSError:
                    return

    def accept() -> None:
        while not stop.is_set():
            try:
                c, _ = server.accept()
            except socket.timeout:
                continue
            threading.Thread(target=serve, args=(c,), daemon=True).start()

    t = threading.Thread(target=accept, daemon=True)
    t.start()
    yield server.getsockname()[:2]
    stop.set()
    t.join(2)
    server.close()


def client(proxy: FaultProxy) -> socket.socket:
    s = socket.create_connection(proxy.address, timeout=5)
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return s


def test_passes_bytes_and_counts_frames(echo: tuple[str, int]) -> None:
    seen: list[tuple[str, int, int, str, int]] = []
    with FaultProxy(echo) as proxy:
        proxy.rule(lambda d, c, f, k, n: seen.append((d, c, f, k, n)) or PASS)
        with client(proxy) as s:
            s.sendall(frame(b"ping .\n") + frame(b"x" * 70000, b"B"))
            assert read_frame(s) == (b"T", b"ping .\n")
            assert read_frame(s) == (b"B", b"x" * 70000)
    assert ("up", 0, 0, "T", 7) in seen and ("up", 0, 1, "B", 70000) in seen
    assert ("down", 0, 0, "T", 7) in seen and ("down", 0, 1, "B", 70000) in seen


def test_delay_applies_to_both_directions(echo: tuple[str, int]) -> None:
    with FaultProxy(echo) as proxy:
        with client(proxy) as s:
            t0 = time.monotonic()
            s.sendall(frame(b"a"))
            read_frame(s)
            fast = time.monotonic() - t0
            proxy.delay(0.15)
            t0 = time.monotonic()
            s.sendall(frame(b"b"))
            assert read_frame(s) == (b"T", b"b")
            slow = time.monotonic() - t0
    assert fast < 0.1
    assert 0.3 <= slow < 1.0, slow  # 0.15 s each way


def test_delay_from_the_start_records_and_counts_connections(echo: tuple[str, int]) -> None:
    with FaultProxy(echo, delay_s=0.1, record=True) as proxy:
        for _ in range(2):
            with client(proxy) as s:
                t0 = time.monotonic()
                s.sendall(b"not a frame at all")  # raw bytes pass (and are recorded) too
                assert read_exact(s, 18) == b"not a frame at all"
                assert 0.2 <= time.monotonic() - t0 < 1.0
        assert proxy.captured_bytes() == b"not a frame at all" * 4  # up and down, twice
        assert proxy.connections == 2
    with FaultProxy(echo) as quiet, client(quiet) as s:
        s.sendall(frame(b"a"))
        read_frame(s)
        assert quiet.captured_bytes() == b""
    with pytest.raises(ValueError):
        FaultProxy(echo, delay_s=-1)


def test_a_slow_reader_gets_every_byte(echo: tuple[str, int]) -> None:
    # more than the socket buffers hold, read only after a pause longer than the proxy's polls
    body = bytes(range(256)) * 40_000
    with FaultProxy(echo) as proxy, client(proxy) as s:
        sender = threading.Thread(target=s.sendall, args=(frame(body, b"B"),), daemon=True)
        sender.start()
        time.sleep(1.0)
        assert read_frame(s) == (b"B", body)
        sender.join(5)


def test_drop_at_frame_n_resets_the_connection(echo: tuple[str, int]) -> None:
    with FaultProxy(echo) as proxy:
        proxy.rule(lambda d, c, f, k, n: DROP if (d, f) == ("up", 2) else PASS)
        with client(proxy) as s:
            for i in range(2):
                s.sendall(frame(b"%d" % i))
                assert read_frame(s) == (b"T", b"%d" % i)
            s.sendall(frame(b"2"))
            with pytest.raises((ConnectionError, OSError)):
                read_frame(s)
        # the next connection is proxied again (frame counts are per connection)
        proxy.rule(None)
        with client(proxy) as s:
            s.sendall(frame(b"again"))
            assert read_frame(s) == (b"T", b"again")


def test_stall_keeps_the_connection_open_and_silent(echo: tuple[str, int]) -> None:
    with FaultProxy(echo) as proxy:
        proxy.rule(lambda d, c, f, k, n: STALL if (d, f) == ("down", 1) else PASS)
        with client(proxy) as s:
            s.sendall(frame(b"0"))
            assert read_frame(s) == (b"T", b"0")
            s.sendall(frame(b"1"))
            s.settimeout(0.8)
            with pytest.raises(socket.timeout):
                s.recv(1)  # stalled: nothing, and not closed
            proxy.cut()  # a cut ends the stall
            s.settimeout(2)
            with pytest.raises((ConnectionError, OSError)):
                read_frame(s)


def test_cut_refuses_until_mend(echo: tuple[str, int]) -> None:
    with FaultProxy(echo) as proxy:
        s = client(proxy)
        s.sendall(frame(b"before"))
        assert read_frame(s) == (b"T", b"before")
        proxy.cut()
        with pytest.raises((ConnectionError, OSError)):
            s.sendall(frame(b"after"))
            read_frame(s)
        s.close()
        with pytest.raises((ConnectionError, OSError)):
            with client(proxy) as s2:
                s2.sendall(frame(b"refused"))
                read_frame(s2)
        proxy.mend()
        with client(proxy) as s3:
            s3.sendall(frame(b"mended"))
            assert read_frame(s3) == (b"T", b"mended")


@pytest.mark.skipif(SWIPL is None, reason="swipl not installed")
def test_platform_node_behind_the_proxy() -> None:
    node = subprocess.Popen(
        [SWIPL, "-q", str(PLATFORM_DIR / "node_main.pl")], stdout=subprocess.PIPE, text=True
    )
    try:
        assert node.stdout is not None
        line = node.stdout.readline()
        port = int(line.rsplit(":", 1)[1])
        kinds: list[tuple[str, str]] = []
        with FaultProxy(("127.0.0.1", port)) as proxy:
            proxy.rule(lambda d, c, f, k, n: kinds.append((d, k)) or PASS)
            with client(proxy) as s:
                kind, hello = read_frame(s)
                assert kind == b"T" and hello.startswith(b"hello(")
                s.sendall(frame(b"ping .\n"))
                kind, reply = read_frame(s)
                assert reply.startswith(b"ok(pong(")
        assert kinds[:3] == [("down", "T"), ("up", "T"), ("down", "T")]
    finally:
        node.kill()
        node.wait(10)
