"""A fault-injecting TCP proxy for the platform's frames: delay, drop, stall, cut, capture.

``FaultProxy(target=(host, port))`` listens on a loopback port (``.address``) and forwards every
connection to ``target``, byte for byte, while it reads the platform's frames in both
directions (12-byte header: ``b"DFRL"``, version, kind ``b"T"``/``b"B"``, 2 reserved bytes, u32
big-endian body length). It counts the connections it forwarded (``.connections``: a pooled
platform connection is one, however many hops use it). The chaos benchmark (:mod:`.chaos`) and
the platform's tests (custody, faults, WAN costs, what crosses the wire) use it. Faults:

- ``delay(seconds)`` (or ``delay_s=`` at the start): every chunk, in both directions, is
  forwarded ``seconds`` after it arrived (order kept; a delay set later applies to chunks read
  later), so a request and its reply cost ``2 * seconds`` more;
- ``rule(fn)``: ``fn(direction, conn, frame, kind, length) -> Action`` is called at the header of
  every frame (``direction`` ``"up"`` client to target or ``"down"``; ``conn`` and ``frame``
  count from 0 per proxy and per direction of a connection). ``PASS`` forwards it, ``DROP``
  closes both sides of the connection abruptly (RST) without forwarding the frame, ``STALL``
  stops forwarding this connection in both directions and keeps it open (until ``cut`` or
  ``close``);
- ``cut()``: close every connection abruptly and refuse new ones (accepted and reset) until
  ``mend()``.

With ``record=True`` it also keeps every byte it reads, both directions interleaved
(:meth:`FaultProxy.captured_bytes`), for tests that look at what crosses the wire.

A stream that stops looking like frames (bad magic, e.g. a binary frame of an older peer whose
length field is 0, or TLS records) is forwarded raw from there on, without further rule calls
(where a header is due, bytes are held until its 12 have come). Every wait is
bounded (socket timeouts and queue polls of at most 0.2 s); ``close()`` joins all threads.
"""

from __future__ import annotations

import enum
import queue
import socket
import struct
import threading
import time
from collections.abc import Callable

HEADER = 12
MAGIC = b"DFRL"
POLL_S = 0.2


class Action(enum.Enum):
    """What a rule does with a frame."""

    PASS = "pass"
    DROP = "drop"
    STALL = "stall"


PASS, DROP, STALL = Action.PASS, Action.DROP, Action.STALL

Rule = Callable[[str, int, int, str, int], Action]


def _abort(sock: socket.socket) -> None:
    """Close ``sock`` with a reset (SO_LINGER 0), ignoring a socket already closed."""
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    except OSError:
        pass
    try:
        sock.close()
    except OSError:
        pass


class _FrameReader:
    """Splits one direction's byte stream at frame headers and asks the rule about each."""

    def __init__(
        self, direction: str, conn: int, decide: Callable[[str, int, int, str, int], Action]
    ):
        self.direction = direction
        self.conn = conn
        self.decide = decide
        self.frame = 0
        self.header = b""
        self.body_left = 0
        self.raw = False

    def feed(self, data: bytes) -> tuple[bytes, Action]:
        """Bytes to forward now, and the action that stops forwarding (PASS if none)."""
        out = bytearray()
        while data:
            if self.raw:
                out += data
                break
            if self.body_left:
                take = data[: self.body_left]
                out += take
                self.body_left -= len(take)
                data = data[len(take) :]
                continue
            need = HEADER - len(self.header)
            self.header += data[:need]
            data = data[need:]
            if len(self.header) < HEADER:
                break
            header, self.header = self.header, b""
            if header[:4] != MAGIC:
                self.raw = True
                out += header
                continue
            kind = header[5:6].decode("latin-1")
            length = struct.unpack(">I", header[8:12])[0]
            action = self.decide(self.direction, self.conn, self.frame, kind, length)
            self.frame += 1
            if action is not PASS:
                return bytes(out), action
            out += header
            self.body_left = length
        return bytes(out), PASS


class _Link:
    """One proxied connection: client and upstream sockets, two readers and two senders."""

    def __init__(
        self, proxy: FaultProxy, conn: int, client: socket.socket, upstream: socket.socket
    ):
        self.proxy = proxy
        self.conn = conn
        self.client = client
        self.upstream = upstream
        self.closed = threading.Event()
        self.stalled = threading.Event()
        self._ends = 0
        self._ends_lock = threading.Lock()
        self.threads: list[threading.Thread] = []
        for direction, src, dst in (("up", client, upstream), ("down", upstream, client)):
            q: queue.Queue[tuple[float, bytes]] = queue.Queue()
            reader = _FrameReader(direction, conn, proxy._decide)
            self.threads.append(
                threading.Thread(
                    target=self._read,
                    args=(src, reader, q),
                    daemon=True,
                    name=f"proxy-{direction}-{conn}",
                )
            )
            self.threads.append(
                threading.Thread(
                    target=self._send,
                    args=(dst, q),
                    daemon=True,
                    name=f"proxy-send-{direction}-{conn}",
                )
            )
        for t in self.threads:
            t.start()

    def _read(self, src: socket.socket, reader: _FrameReader, q: queue.Queue) -> None:
        src.settimeout(POLL_S)
        while not self.closed.is_set():
            if self.stalled.is_set():
                time.sleep(POLL_S / 2)
                continue
            try:
                data = src.recv(65536)
            except socket.timeout:
                continue
            except OSError:
                self.abort()
                return
            if not data:
                break
            self.proxy._record(data)
            out, action = reader.feed(data)
            if out:
                q.put((time.monotonic() + self.proxy.delay_s, out))
            if action is DROP:
                self.abort()
                return
            if action is STALL:
                self.stalled.set()
        q.put((0.0, b""))  # end of stream: the sender half-closes after what is queued

    def _send(self, dst: socket.socket, q: queue.Queue) -> None:
        while not self.closed.is_set():
            try:
                due, data = q.get(timeout=POLL_S)
            except queue.Empty:
                continue
            while not self.closed.is_set() and time.monotonic() < due:
                time.sleep(min(POLL_S, due - time.monotonic()))
            while self.stalled.is_set() and not self.closed.is_set():
                time.sleep(POLL_S / 2)
            if self.closed.is_set():
                return
            try:
                if data:
                    self._send_all(dst, data)
                else:
                    dst.shutdown(socket.SHUT_WR)
                    self._one_end()
                    return
            except OSError:
                self.abort()
                return

    def _send_all(self, dst: socket.socket, data: bytes) -> None:
        """Send ``data`` whole, however long the peer takes to read it (the socket's timeout
        is the readers' poll), unless the link closes meanwhile."""
        view = memoryview(data)
        while view and not self.closed.is_set():
            try:
                view = view[dst.send(view) :]
            except socket.timeout:
                continue

    def _one_end(self) -> None:
        """A direction ended cleanly; after both, close the sockets."""
        with self._ends_lock:
            self._ends += 1
            both = self._ends == 2
        if both and not self.closed.is_set():
            self.closed.set()
            for s in (self.client, self.upstream):
                try:
                    s.close()
                except OSError:
                    pass

    def abort(self) -> None:
        """Reset both sides now."""
        if not self.closed.is_set():
            self.closed.set()
            _abort(self.client)
            _abort(self.upstream)

    def finished(self) -> bool:
        return all(not t.is_alive() for t in self.threads)

    def join(self, timeout: float) -> None:
        deadline = time.monotonic() + timeout
        for t in self.threads:
            if t is not threading.current_thread():
                t.join(max(0.0, deadline - time.monotonic()))


class FaultProxy:
    """Forward connections from ``listen`` to ``target`` with injectable faults.

    Parameters
    ----------
    target
        ``(host, port)`` of the platform node behind the proxy.
    listen
        Address to listen on (default: an OS-chosen loopback port).
    connect_timeout
        Seconds to wait for the target when a client connects; a client whose target cannot be
        reached is reset.
    delay_s
        The delay of every chunk from the start (:meth:`delay`).
    record
        Keep every byte read (:meth:`captured_bytes`).
    """

    def __init__(
        self,
        target: tuple[str, int],
        listen: tuple[str, int] = ("127.0.0.1", 0),
        connect_timeout: float = 2.0,
        *,
        delay_s: float = 0.0,
        record: bool = False,
    ) -> None:
        self.target = target
        self.connect_timeout = connect_timeout
        self.delay_s = 0.0
        self.delay(delay_s)
        self.connections = 0
        self._recording = record
        self._captured = bytearray()
        self._rule: Rule | None = None
        self._cut = False
        self._lock = threading.Lock()
        self._links: dict[int, _Link] = {}
        self._server = socket.create_server(listen)
        self._server.settimeout(POLL_S)
        self._closing = threading.Event()
        host, port = self._server.getsockname()[:2]
        self.address: tuple[str, int] = (host, port)
        self._acceptor = threading.Thread(target=self._accept, daemon=True, name="proxy-accept")
        self._acceptor.start()

    # -- faults ------------------------------------------------------------------------------
    def delay(self, seconds: float) -> None:
        """Forward every chunk read from now on ``seconds`` late (0 for none)."""
        if seconds < 0:
            raise ValueError("delay must be >= 0")
        self.delay_s = float(seconds)

    def captured_bytes(self) -> bytes:
        """Every byte read so far, both directions interleaved (with ``record=True``; else
        none)."""
        with self._lock:
            return bytes(self._captured)

    def rule(self, fn: Rule | None) -> None:
        """Ask ``fn`` about every frame from now on (None: pass everything)."""
        self._rule = fn

    def cut(self) -> None:
        """Reset every connection and refuse new ones until :meth:`mend`."""
        with self._lock:
            self._cut = True
            links = list(self._links.values())
        for link in links:
            link.abort()

    def mend(self) -> None:
        """Accept connections again."""
        with self._lock:
            self._cut = False

    def close(self) -> None:
        """Stop listening, reset every connection and join every thread (bounded)."""
        self._closing.set()
        self.cut()
        self._acceptor.join(5)
        self._server.close()
        with self._lock:
            links = list(self._links.values())
            self._links.clear()
        for link in links:
            link.join(5)

    def __enter__(self) -> FaultProxy:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- machinery ---------------------------------------------------------------------------
    def _record(self, data: bytes) -> None:
        if self._recording:
            with self._lock:
                self._captured += data

    def _decide(self, direction: str, conn: int, frame: int, kind: str, length: int) -> Action:
        fn = self._rule
        if fn is None:
            return PASS
        action = fn(direction, conn, frame, kind, length)
        if not isinstance(action, Action):
            raise TypeError(f"a rule must return an Action, not {action!r}")
        return action

    def _accept(self) -> None:
        while not self._closing.is_set():
            try:
                client, _ = self._server.accept()
            except socket.timeout:
                self._reap()
                continue
            except OSError:
                return
            with self._lock:
                refused = self._cut or self._closing.is_set()
            if refused:
                _abort(client)
                continue
            try:
                upstream = socket.create_connection(self.target, timeout=self.connect_timeout)
            except OSError:
                _abort(client)
                continue
            for s in (client, upstream):
                s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                conn = self.connections
                self.connections += 1
                self._links[conn] = _Link(self, conn, client, upstream)
                if self._cut:
                    self._links[conn].abort()

    def _reap(self) -> None:
        with self._lock:
            done = [
                c for c, link in self._links.items() if link.closed.is_set() and link.finished()
            ]
            for c in done:
                del self._links[c]
