"""A minimal client of the platform's text frames, for tests from Python."""
from __future__ import annotations

import socket
import struct

MAGIC = b"DFRL"
VERSION = 1


def frame(body: bytes, kind: bytes = b"T", length: int | None = None) -> bytes:
    """A frame with ``body``; ``length`` overrides the header's length field."""
    n = len(body) if length is None else length
    return MAGIC + bytes([VERSION]) + kind + b"\0\0" + struct.pack(">I", n) + body


def read_frame(sock: socket.socket) -> tuple[bytes, str] | None:
    """Read one text frame; None if the peer closed the connection."""
    header = _read_exact(sock, 12)
    if header is None:
        return None
    assert header[:4] == MAGIC, header
    (n,) = struct.unpack(">I", header[8:12])
    body = _read_exact(sock, n)
    assert body is not None
    return header[5:6], body.decode("utf-8")


def _read_exact(sock: socket.socket, n: int) -> bytes | None:
    buf = b""
    while len(buf) < n:
        chunk = sock.recv(n - len(buf))
        if not chunk:
            return None
        buf += chunk
    return buf


def connect(port: int, timeout: float = 5.0) -> socket.socket:
    """Connect and consume the hello frame."""
    s = socket.create_connection(("127.0.0.1", port), timeout=timeout)
    hello = read_frame(s)
    assert hello is not None and hello[1].startswith("hello("), hello
    return s


def request(port: int, text: str) -> str:
    """Send one text request (a Prolog term, no final dot) and return the reply text."""
    with connect(port) as s:
        s.sendall(frame(f"{text} .\n".encode()))
        reply = read_frame(s)
        assert reply is not None
        return reply[1]
