"""A minimal client of the platform's text frames, for tests from Python."""

from __future__ import annotations

import hashlib
import hmac
import re
import socket
import struct

MAGIC = b"DFRL"
VERSION = 1


def frame(body: bytes, kind: bytes = b"T", length: int | None = None) -> bytes:
    """A frame with ``body``; ``length`` overrides the header's length field."""
    n = len(body) if length is None else length
    return MAGIC + bytes([VERSION]) + kind + b"\0\0" + struct.pack(">I", n) + body


def read_frame(sock: socket.socket) -> tuple[bytes, str] | None:
    """Read one frame: (kind, body); None if the peer closed the connection.

    Both kinds carry their body length in the header. A text body is decoded as UTF-8; a
    binary body (SWI-Prolog's fast serialization) is given as latin-1 text, byte for byte.
    """
    header = _read_exact(sock, 12)
    if header is None:
        return None
    assert header[:4] == MAGIC, header
    (n,) = struct.unpack(">I", header[8:12])
    body = _read_exact(sock, n)
    assert body is not None
    kind = header[5:6]
    return kind, body.decode("utf-8" if kind == b"T" else "latin-1")


OPEN_KEY = "'dfrl-open-platform'"
"""The open key as the platform writes it (``~q``): the HMAC key an open platform accepts."""


def token_proof(key_text: str, nonce: str) -> str:
    """Hex HMAC-SHA256 of ``nonce`` keyed by a token's canonical text (e.g. ``"55"``)."""
    return hmac.new(key_text.encode(), nonce.encode(), hashlib.sha256).hexdigest()


def open_proof(nonce: str) -> str:
    """The proof of the open key for ``nonce``."""
    return token_proof(OPEN_KEY, nonce)


def _read_exact(sock: socket.socket, n: int) -> bytes | None:
    buf = b""
    while len(buf) < n:
        chunk = sock.recv(n - len(buf))
        if not chunk:
            return None
        buf += chunk
    return buf


def connect(port: int, timeout: float = 5.0, source: str | None = None) -> socket.socket:
    """Connect (from the loopback address ``source`` if given) and consume the hello frame."""
    s, _ = connect_nonce(port, timeout, source)
    return s


def connect_nonce(
    port: int, timeout: float = 5.0, source: str | None = None
) -> tuple[socket.socket, str]:
    """Connect, read the hello; give the socket and the hello's nonce."""
    src = (source, 0) if source else None
    s = socket.create_connection(("127.0.0.1", port), timeout=timeout, source_address=src)
    hello = read_frame(s)
    assert hello is not None and hello[1].startswith("hello("), hello
    return s, hello_nonce(hello[1])


def hello_nonce(hello: str) -> str:
    """The nonce of a hello frame's text: ``hello(1,'0a..',node(...))``."""
    m = re.match(r"hello\(\d+,'?([0-9a-f]+)'?,", hello)
    assert m, hello
    return m.group(1)


def authenticate(s: socket.socket, nonce: str, key_text: str) -> str:
    """Send auth with the proof of one token (its canonical text, e.g. ``"9"``); give the verdict."""
    s.sendall(frame(f"auth(['{token_proof(key_text, nonce)}']) .\n".encode()))
    verdict = read_frame(s)
    assert verdict is not None
    return verdict[1]


def connect_auth(
    port: int, key_text: str, timeout: float = 5.0, source: str | None = None
) -> socket.socket:
    """A connection on which the token ``key_text`` was proved."""
    s, nonce = connect_nonce(port, timeout, source)
    verdict = authenticate(s, nonce, key_text)
    assert verdict.startswith("ok(authenticated)"), verdict
    return s


def request(port: int, text: str, token: str | None = None) -> str:
    """Send one text request (a Prolog term, no final dot) and return the reply text.

    With ``token`` (a token's canonical text) the request is sent after a proof of it.
    """
    with connect_auth(port, token) if token is not None else connect(port) as s:
        s.sendall(frame(f"{text} .\n".encode()))
        reply = read_frame(s)
        assert reply is not None
        return reply[1]
