"""Mutual TLS (issue 9): a TLS node refuses plaintext peers, peers without a certificate and
peers whose certificate another CA signed; a stalled handshake is closed within the
pre-authentication deadline; ``tls_peers(Names)`` refuses agents and code from other names.

The clients are Python's ``ssl`` sockets speaking the platform's frames (as
``wire_client.py`` does in plaintext), so each case is one real handshake against a real node.
"""

from __future__ import annotations

import shutil
import socket
import ssl
import time
from pathlib import Path

import pytest

from dfrl.experiments.tools.certs import init_ca, make_node

from . import hostile_node
from .conftest import Proc
from .wire_client import frame, hello_nonce, read_frame, token_proof

pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="openssl missing")

TOKEN = "9"


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A project CA with nodes alpha, beta and client; another CA with mallory."""
    root = tmp_path_factory.mktemp("pki")
    init_ca(root / "ca")
    init_ca(root / "other")
    dirs = {n: make_node(n, root / "ca").directory for n in ("alpha", "beta", "client")}
    dirs["mallory"] = make_node("mallory", root / "other").directory
    return dirs


def _tls_client(node_dir: Path | None, ca: Path) -> ssl.SSLContext:
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    ctx.check_hostname = False  # names are checked by allow-list, not host name
    ctx.load_verify_locations(ca / "ca.crt")
    if node_dir is not None:
        ctx.load_cert_chain(node_dir / "node.crt", node_dir / "node.key")
    return ctx


def _connect(port: int, ctx: ssl.SSLContext, timeout: float = 5.0) -> tuple[ssl.SSLSocket, str]:
    raw = socket.create_connection(("127.0.0.1", port), timeout=timeout)
    s = ctx.wrap_socket(raw)
    hello = read_frame(s)
    assert hello is not None and hello[1].startswith("hello("), hello
    return s, hello_nonce(hello[1])


def _request(s: ssl.SSLSocket, nonce: str, text: str) -> str:
    s.sendall(frame(f"auth(['{token_proof(TOKEN, nonce)}']) .\n".encode()))
    verdict = read_frame(s)
    assert verdict is not None and verdict[1].startswith("ok(authenticated)"), verdict
    s.sendall(frame(f"{text} .\n".encode()))
    reply = read_frame(s)
    assert reply is not None
    return reply[1]


def _until_closed(s: socket.socket, limit: int = 100) -> bytes:
    data = b""
    for _ in range(limit):
        chunk = s.recv(4096)
        if not chunk:
            return data
        data += chunk
    raise AssertionError(f"the node kept the connection open: {data!r}")


def _tls_node(
    procs: list[Proc], tmp_path: Path, node_dir: Path, extra: str = "", flags: tuple[str, ...] = ()
) -> int:
    _, port = hostile_node.start(
        procs,
        tmp_path,
        f"[token({TOKEN}), tls({str(node_dir)!r}), frame_deadline(1){extra}]",
        flags=flags,
    )
    return port


def test_a_peer_with_a_certificate_of_the_ca_is_served(
    pki: dict[str, Path], tmp_path: Path, procs: list[Proc]
) -> None:
    port = _tls_node(procs, tmp_path, pki["alpha"])
    s, nonce = _connect(port, _tls_client(pki["client"], pki["alpha"]))
    with s:
        assert s.version() in ("TLSv1.2", "TLSv1.3")
        # the server's certificate names it; ours was verified by the node
        cn = dict(x[0] for x in s.getpeercert()["subject"])["commonName"]
        assert cn == "alpha"
        assert _request(s, nonce, "agents").startswith("ok(")


@pytest.mark.parametrize("flags", [(), ("--no-signals",)], ids=["signals", "no-signals"])
def test_plaintext_peer_is_refused_within_the_deadline(
    pki: dict[str, Path], tmp_path: Path, procs: list[Proc], flags: tuple[str, ...]
) -> None:
    # --no-signals: as a robot process's Prolog runs (pyswip), where the handshake's alarm
    # cannot interrupt a read and only the plain stream's own timeout ends it
    port = _tls_node(procs, tmp_path, pki["alpha"], flags=flags)
    # a plaintext client waits for a hello that never comes: a TLS alert at most, then the
    # node closes at the 1 s handshake deadline
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        t0 = time.monotonic()
        data = _until_closed(s)
        assert time.monotonic() - t0 < 5
        assert b"DFRL" not in data and b"hello" not in data, data
    # a plaintext client that talks first gets no frame either
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        s.sendall(frame(b"ping .\n"))
        data = _until_closed(s)
        assert b"DFRL" not in data and b"pong" not in data, data
    # the node still serves a TLS peer
    s2, _ = _connect(port, _tls_client(pki["client"], pki["alpha"]))
    s2.close()


def test_stalled_handshake_does_not_hold_a_slot(
    pki: dict[str, Path], tmp_path: Path, procs: list[Proc]
) -> None:
    port = _tls_node(procs, tmp_path, pki["alpha"], ", max_connections(4)")
    # more stalled handshakes than slots, each sending one byte of a ClientHello a second
    stalled = [socket.create_connection(("127.0.0.1", port), timeout=10) for _ in range(6)]
    try:
        for _ in range(2):
            for s in stalled:
                try:
                    s.sendall(b"\x16")
                except OSError:
                    pass
            time.sleep(0.5)
        s, nonce = _connect(port, _tls_client(pki["client"], pki["alpha"]), timeout=10)
        with s:
            assert _request(s, nonce, "agents").startswith("ok(")
    finally:
        for s in stalled:
            s.close()


@pytest.mark.parametrize("who", ["mallory", None])
def test_certificate_of_another_ca_or_none_is_refused(
    who: str | None, pki: dict[str, Path], tmp_path: Path, procs: list[Proc]
) -> None:
    port = _tls_node(procs, tmp_path, pki["alpha"])
    # trust the node's CA ourselves: the refusal must come from the node
    ctx = _tls_client(pki[who] if who else None, pki["alpha"])
    with pytest.raises((ssl.SSLError, ConnectionError, AssertionError)):
        s, _ = _connect(port, ctx)
        s.close()


def test_tls_peers_refuses_an_unlisted_name(
    pki: dict[str, Path], tmp_path: Path, procs: list[Proc]
) -> None:
    port = _tls_node(procs, tmp_path, pki["alpha"], ", tls_peers([beta])")
    # the sender is 'client', a name the CA signed but not listed
    requests = [
        'load_code(x, "foo.")',
        "execute(nobody, main)",
        "commit(m1)",
        "transfer(m1, move, s, 0, rec, 1)",
    ]
    s, nonce = _connect(port, _tls_client(pki["client"], pki["alpha"]))
    with s:
        first = _request(s, nonce, requests[0])
        assert "permission_error(request,platform," in first, first
        for text in requests[1:]:
            s.sendall(frame(f"{text} .\n".encode()))
            reply = read_frame(s)
            assert reply is not None and "permission_error(request,platform," in reply[1], reply
        # listings are not agents or code: still served
        s.sendall(frame(b"agents .\n"))
        reply = read_frame(s)
        assert reply is not None and reply[1].startswith("ok("), reply
    # the listed name gets past the allow-list (to the request's own answer)
    s, nonce = _connect(port, _tls_client(pki["beta"], pki["alpha"]))
    with s:
        reply = _request(s, nonce, "commit(m1)")
        assert reply.startswith("ok(not_staged)"), reply
