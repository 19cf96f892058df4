"""The attackers of ``dfrl bench hostile``: unauthenticated peers that speak the platform's wire.

Every attacker sends only to 127.0.0.1 (from loopback source addresses, so that the node's
per-peer and total caps are both tried), runs in its own thread, and stops when told or at its
own deadline. Each counts what became of its connections:

``opened``
    TCP connections established (``connect_failed``: refused or timed out before that).
``deadline``, ``refused``, ``rejected``, ``closed``, ``reset``
    closed by the node: after an error frame naming the whole-frame deadline, after a
    ``resource_error(connections)`` frame, after another error frame (too large, too deep,
    binary before authentication, ...), without an error frame (evicted at a cap, idle), or
    with a connection reset.
``held_at_end``
    still open when the attack was stopped (then closed by the attacker).
"""

from __future__ import annotations

import errno
import selectors
import socket
import struct
import threading
import time
from dataclasses import dataclass, field

MAGIC = b"DFRL"
VERSION = 1
HEADER = 12
OUTCOMES = ("deadline", "refused", "rejected", "closed", "reset")
FRAME_KINDS = ("chain_big", "nested_big", "binary_big", "chain_limit", "nested_limit", "call_limit")
PRE_AUTH_LIMIT = 4096  # the node's max_text_frame_size default (node.pl), tested


def frame_header(length: int, kind: bytes = b"T") -> bytes:
    """The 12-byte header of a frame whose body is ``length`` bytes."""
    return MAGIC + bytes([VERSION]) + kind + b"\0\0" + struct.pack(">I", length)


def sources(n: int) -> list[str]:
    """``n`` loopback source addresses for the attackers: 127.0.0.2, 127.0.0.3, ..."""
    if not 1 <= n <= 200:
        raise ValueError(f"sources must be in 1..200, not {n}")
    return [f"127.0.0.{2 + i}" for i in range(n)]


def outcome_of(received: bytes) -> str:
    """How the node ended a connection, from the bytes it sent (hello, then maybe an error)."""
    frames: list[bytes] = []
    rest = received
    while len(rest) >= HEADER and rest[:4] == MAGIC:
        (n,) = struct.unpack(">I", rest[8:HEADER])
        frames.append(rest[HEADER : HEADER + n])
        rest = rest[HEADER + n :]
    errors = [f for f in frames if f.startswith(b"error(")]
    if not errors:
        return "closed"
    text = errors[-1]
    if b"deadline" in text:
        return "deadline"
    if b"resource_error(connections)" in text:
        return "refused"
    return "rejected"


@dataclass
class Counts:
    """What became of an attacker's connections (see the module doc)."""

    attempted: int = 0
    opened: int = 0
    connect_failed: int = 0
    held_at_end: int = 0
    bytes_sent: int = 0
    outcomes: dict[str, int] = field(default_factory=lambda: {k: 0 for k in OUTCOMES})
    reasons: dict[str, int] = field(default_factory=dict)

    def ended(self, outcome: str, received: bytes = b"") -> None:
        self.outcomes[outcome] += 1
        if outcome == "rejected":
            reason = _reason(received)
            self.reasons[reason] = self.reasons.get(reason, 0) + 1

    def as_dict(self) -> dict:
        closed = sum(self.outcomes.values())
        return {
            "attempted": self.attempted,
            "opened": self.opened,
            "connect_failed": self.connect_failed,
            "closed_by_node": closed,
            **self.outcomes,
            "held_at_end": self.held_at_end,
            "bytes_sent": self.bytes_sent,
            "reject_reasons": self.reasons,
        }


def _reason(received: bytes) -> str:
    """A short name for an error frame's reason: ``too_large``, ``too_deep``, ..."""
    for key in (b"too_large", b"too_deep", b"binary_not_allowed", b"syntax", b"pipelined"):
        if key in received:
            return key.decode()
    return "other"


class _Slot:
    __slots__ = ("sock", "state", "due", "received", "sent")

    def __init__(self) -> None:
        self.sock: socket.socket | None = None
        self.state = "idle"  # idle | connecting | open
        self.due = 0.0  # next connect (idle) or next byte (open)
        self.received = b""
        self.sent = 0


class Swarm(threading.Thread):
    """``n`` connections kept open (a flood) or trickling one byte a second each (slowloris).

    A connection the node closes is opened again ``reconnect_s`` later, as an attacker would;
    a trickler sends the bytes of one text frame declaring a body just under the pre-auth
    limit, one byte every ``trickle_s``. One thread, one selector, non-blocking sockets.
    """

    def __init__(
        self,
        port: int,
        n: int,
        srcs: list[str],
        trickle: bool,
        reconnect_s: float = 1.0,
        trickle_s: float = 1.0,
        max_s: float = 600.0,
    ) -> None:
        super().__init__(daemon=True, name="hostile-swarm")
        if n < 1:
            raise ValueError("a swarm needs at least one connection")
        self.port, self.srcs, self.trickle = port, srcs, trickle
        self.reconnect_s, self.trickle_s, self.max_s = reconnect_s, trickle_s, max_s
        self.slots = [_Slot() for _ in range(n)]
        self.counts = Counts()
        self.stopping = threading.Event()
        body = PRE_AUTH_LIMIT - 16
        self.payload = frame_header(body) + b"a" * body
        self.error: BaseException | None = None

    def stop(self) -> dict:
        """Stop, close what is still open, give the counts."""
        self.stopping.set()
        self.join(timeout=30)
        if self.is_alive():
            raise RuntimeError("attacker did not stop within 30 s")
        if self.error is not None:
            raise RuntimeError(f"attacker failed: {self.error!r}")
        return self.counts.as_dict()

    def run(self) -> None:
        sel = selectors.DefaultSelector()
        end = time.monotonic() + self.max_s
        try:
            while not self.stopping.is_set() and time.monotonic() < end:
                now = time.monotonic()
                started = 0
                for i, slot in enumerate(self.slots):
                    if slot.state == "idle" and now >= slot.due and started < 50:
                        started += 1
                        self._connect(sel, slot, self.srcs[i % len(self.srcs)])
                    elif slot.state == "open" and self.trickle and now >= slot.due:
                        self._send_byte(sel, slot, now)
                for key, mask in sel.select(timeout=0.05):
                    slot = key.data
                    if slot.state == "connecting" and mask & selectors.EVENT_WRITE:
                        self._connected(sel, slot)
                    elif slot.state == "open" and mask & selectors.EVENT_READ:
                        self._read(sel, slot)
        except BaseException as exc:  # noqa: BLE001 - reported by stop()
            self.error = exc
        finally:
            for slot in self.slots:
                if slot.state == "open":
                    self.counts.held_at_end += 1
                if slot.sock is not None:
                    self._close(sel, slot, None)
            sel.close()

    def _connect(self, sel: selectors.BaseSelector, slot: _Slot, src: str) -> None:
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        s.setblocking(False)
        s.bind((src, 0))
        self.counts.attempted += 1
        rc = s.connect_ex(("127.0.0.1", self.port))
        slot.sock, slot.received, slot.sent = s, b"", 0
        if rc not in (0, errno.EINPROGRESS):
            self.counts.connect_failed += 1
            self._close(sel, slot, None)
            return
        slot.state = "connecting"
        slot.due = time.monotonic() + 5.0
        sel.register(s, selectors.EVENT_WRITE, slot)

    def _connected(self, sel: selectors.BaseSelector, slot: _Slot) -> None:
        assert slot.sock is not None
        if slot.sock.getsockopt(socket.SOL_SOCKET, socket.SO_ERROR) != 0:
            self.counts.connect_failed += 1
            self._close(sel, slot, None)
            return
        self.counts.opened += 1
        slot.state = "open"
        slot.due = time.monotonic()
        sel.modify(slot.sock, selectors.EVENT_READ, slot)

    def _send_byte(self, sel: selectors.BaseSelector, slot: _Slot, now: float) -> None:
        assert slot.sock is not None
        try:
            slot.sock.send(self.payload[slot.sent % len(self.payload) :][:1])
            slot.sent += 1
            self.counts.bytes_sent += 1
            slot.due = now + self.trickle_s
        except BlockingIOError:
            slot.due = now + self.trickle_s
        except OSError:
            self._close(sel, slot, "reset")

    def _read(self, sel: selectors.BaseSelector, slot: _Slot) -> None:
        assert slot.sock is not None
        try:
            data = slot.sock.recv(4096)
        except BlockingIOError:
            return
        except OSError:
            self._close(sel, slot, "reset")
            return
        if not data:
            self._close(sel, slot, outcome_of(slot.received))
        elif len(slot.received) < 8192:
            slot.received += data

    def _close(self, sel: selectors.BaseSelector, slot: _Slot, outcome: str | None) -> None:
        if outcome is not None:
            self.counts.ended(outcome, slot.received)
        if slot.sock is not None:
            try:
                sel.unregister(slot.sock)
            except (KeyError, ValueError):
                pass
            slot.sock.close()
        slot.sock, slot.state = None, "idle"
        slot.due = time.monotonic() + self.reconnect_s


def hostile_frame(kind: str, size: int) -> bytes:
    """One hostile frame (header and body) of kind ``kind`` (see :data:`FRAME_KINDS`).

    ``*_big``: ``size`` bytes (``a+a+...``, ``[[[...]]]``, or a binary body of zeros) far over
    the pre-authentication limit; ``*_limit``: ``a+a+...``, ``[[[...]]]`` and ``f(f(...))``
    just under that limit (:data:`PRE_AUTH_LIMIT`), so that the node must read them.
    """
    big = kind.endswith("_big")
    n = size if big else PRE_AUTH_LIMIT - 64
    if kind.startswith("chain"):
        body = b"a+" * ((n - 4) // 2) + b"a .\n"
    elif kind.startswith("nested"):
        depth = (n - 3) // 2
        body = b"[" * depth + b"]" * depth + b" .\n"
    elif kind == "call_limit":
        depth = (n - 4) // 3
        body = b"f(" * depth + b"a" + b")" * depth + b" .\n"
    elif kind == "binary_big":
        return frame_header(n, b"B") + b"\0" * n
    else:
        raise ValueError(f"unknown frame kind {kind!r}; choose from {FRAME_KINDS}")
    return frame_header(len(body)) + body


class FrameSenders:
    """``n`` threads, each sending hostile frames one connection at a time (``kinds`` in turn by
    thread), waiting for the node's answer or close, pausing ``pause_s``, and again."""

    def __init__(
        self,
        port: int,
        n: int,
        size: int,
        srcs: list[str],
        pause_s: float = 0.25,
        max_s: float = 600.0,
        kinds: tuple[str, ...] = FRAME_KINDS,
    ) -> None:
        if n < 1 or size < 1 or not kinds:
            raise ValueError("frames >= 1 and frame size >= 1 are required")
        self.port, self.srcs, self.pause_s, self.max_s = port, srcs, pause_s, max_s
        self.kinds = kinds
        self.frames = {k: hostile_frame(k, size) for k in kinds}
        self.counts = Counts()
        self.by_kind = {k: 0 for k in kinds}
        self.lock = threading.Lock()
        self.stopping = threading.Event()
        self.errors: list[str] = []
        self.threads = [
            threading.Thread(target=self._loop, args=(i,), daemon=True, name=f"hostile-frames-{i}")
            for i in range(n)
        ]

    def start(self) -> None:
        for t in self.threads:
            t.start()

    def stop(self) -> dict:
        self.stopping.set()
        for t in self.threads:
            t.join(timeout=30)
        if any(t.is_alive() for t in self.threads):
            raise RuntimeError("frame senders did not stop within 30 s")
        if self.errors:
            raise RuntimeError(f"frame sender failed: {self.errors[0]}")
        return {**self.counts.as_dict(), "frames_by_kind": self.by_kind}

    def _loop(self, i: int) -> None:
        kind = self.kinds[i % len(self.kinds)]
        end = time.monotonic() + self.max_s
        try:
            while not self.stopping.is_set() and time.monotonic() < end:
                outcome, received, sent, opened = self._one(
                    self.srcs[i % len(self.srcs)], self.frames[kind]
                )
                with self.lock:
                    self.counts.attempted += 1
                    self.counts.opened += opened
                    self.counts.connect_failed += 1 - opened
                    self.counts.bytes_sent += sent
                    if outcome == "held":
                        self.counts.held_at_end += 1
                    elif outcome is not None:
                        self.counts.ended(outcome, received)
                        self.by_kind[kind] += 1
                self.stopping.wait(self.pause_s)
        except Exception as exc:  # noqa: BLE001 - reported by stop()
            self.errors.append(repr(exc))

    def _one(self, src: str, data: bytes) -> tuple[str | None, bytes, int, int]:
        """Send one frame on a new connection; (outcome, bytes received, bytes sent, opened)."""
        try:
            s = socket.create_connection(
                ("127.0.0.1", self.port), timeout=5.0, source_address=(src, 0)
            )
        except OSError:
            return None, b"", 0, 0
        received, sent = b"", 0
        with s:
            try:
                s.sendall(data)
                sent = len(data)
            except OSError:
                pass  # the node stopped reading (refused at the header)
            s.settimeout(10.0)
            deadline = time.monotonic() + 15.0
            try:
                while time.monotonic() < deadline and not self.stopping.is_set():
                    chunk = s.recv(4096)
                    if not chunk:
                        return outcome_of(received), received, sent, 1
                    received += chunk[: max(0, 8192 - len(received))]
            except (TimeoutError, socket.timeout):
                return "held", received, sent, 1
            except OSError:
                out = outcome_of(received)
                return (out if out != "closed" else "reset"), received, sent, 1
        return "held", received, sent, 1
