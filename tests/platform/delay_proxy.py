"""A TCP proxy on loopback that delays every chunk, to measure WAN costs in tests.

Each accepted connection gets its own connection to the target. Every chunk read from one
side is forwarded to the other ``delay`` seconds after it was read, in order, so a request
and its reply cost one round trip of ``2 * delay``. The proxy counts the connections it
accepted (a pooled platform connection is one connection however many hops use it). With
``record=True`` it also keeps every byte it forwards, both ways (:meth:`captured_bytes`), for
the tests that look at what crosses the wire.
"""
from __future__ import annotations

import queue
import socket
import threading
import time


class DelayProxy:
    """Forward ``listen`` to ``target`` with ``delay`` seconds each way."""

    def __init__(self, target: tuple[str, int], delay: float,
                 listen: tuple[str, int] = ("127.0.0.1", 0), record: bool = False) -> None:
        self.target = target
        self.delay = delay
        self.accepted = 0
        self._record = record
        self._captured = bytearray()
        self._server = socket.create_server(listen)
        self._server.settimeout(0.2)
        self._closing = threading.Event()
        self._socks: list[socket.socket] = []
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._accept_loop, daemon=True)
        self._thread.start()

    def captured_bytes(self) -> bytes:
        """Every byte forwarded so far, both directions interleaved (``record=True``)."""
        with self._lock:
            return bytes(self._captured)

    @property
    def address(self) -> tuple[str, int]:
        host, port = self._server.getsockname()[:2]
        return str(host), int(port)

    def close(self) -> None:
        self._closing.set()
        self._thread.join(timeout=5)
        self._server.close()
        with self._lock:
            for s in self._socks:
                try:
                    s.close()
                except OSError:
                    pass

    def __enter__(self) -> DelayProxy:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _accept_loop(self) -> None:
        while not self._closing.is_set():
            try:
                down, _ = self._server.accept()
            except TimeoutError:
                continue
            except OSError:
                return
            try:
                up = socket.create_connection(self.target, timeout=5)
            except OSError:
                down.close()
                continue
            for s in (down, up):
                s.settimeout(None)
                s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                self.accepted += 1
                self._socks += [down, up]
            for src, dst in ((down, up), (up, down)):
                chunks: queue.Queue[tuple[float, bytes]] = queue.Queue()
                threading.Thread(target=self._read, args=(src, chunks), daemon=True).start()
                threading.Thread(target=self._write, args=(dst, chunks), daemon=True).start()

    def _read(self, src: socket.socket, chunks: queue.Queue[tuple[float, bytes]]) -> None:
        while True:
            try:
                data = src.recv(65536)
            except OSError:
                data = b""
            if self._record and data:
                with self._lock:
                    self._captured += data
            chunks.put((time.monotonic() + self.delay, data))
            if not data:
                return

    def _write(self, dst: socket.socket, chunks: queue.Queue[tuple[float, bytes]]) -> None:
        while True:
            due, data = chunks.get()
            wait = due - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            try:
                if data:
                    dst.sendall(data)
                else:
                    dst.shutdown(socket.SHUT_WR)
                    return
            except OSError:
                return
