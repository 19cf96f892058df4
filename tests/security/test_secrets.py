"""Secrets that cannot be brute-forced (issue 9): weak tokens refused off loopback, strong ones
printed by ``dfrl secret``, nonces from the crypto generator, tokens never on the wire."""

from __future__ import annotations

import argparse
import re
import subprocess

from dfrl.experiments.tokens import env_with_tokens, new_secret
from dfrl.platform_pl import PLATFORM_DIR
from tests.platform.conftest import Proc, start_node
from tests.platform.wire_client import connect_auth, connect_nonce, frame, read_frame
from dfrl.experiments.processes import find_swipl

SWIPL = find_swipl()
NODE_MAIN = str(PLATFORM_DIR / "node_main.pl")


def _run_node(*args: str, timeout: float = 10) -> subprocess.CompletedProcess[str]:
    assert SWIPL
    return subprocess.run(
        [SWIPL, "-q", NODE_MAIN, *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        stdin=subprocess.DEVNULL,
    )


def test_weak_token_refused_off_loopback() -> None:
    run = _run_node("--host", "0.0.0.0", "--port", "0", "--token", "1111")
    assert run.returncode == 1, run
    assert "11 bits" in run.stderr and "128" in run.stderr, run.stderr
    run = _run_node("--host", "0.0.0.0", "--port", "0")  # open: no token at all
    assert run.returncode == 1 and "0 bits" in run.stderr, run


def test_insecure_or_strong_token_starts_off_loopback(procs: list[Proc]) -> None:
    p, _ = start_node(procs, "--host", "0.0.0.0", "--port", "0", "--token", "1111", "--insecure")
    assert "INSECURE" in p.output()
    p2, port = start_node(
        procs, "--host", "0.0.0.0", "--port", "0", env=env_with_tokens([new_secret()])
    )
    assert "Warning" not in p2.output() and "INSECURE" not in p2.output()


def test_integer_token_on_loopback_works_with_a_warning(procs: list[Proc]) -> None:
    p, port = start_node(procs, "--port", "0", "--token", "1111")
    p.wait_for("loopback only")
    with connect_auth(port, "1111") as s:
        s.sendall(frame(b"agents .\n"))
        reply = read_frame(s)
        assert reply is not None and reply[1].startswith("ok(")


def test_dfrl_secret_prints_a_strong_token(capsys) -> None:  # type: ignore[no-untyped-def]
    from dfrl.experiments.cli import secret

    parser = argparse.ArgumentParser()
    secret.register(parser.add_subparsers())
    args = parser.parse_args(["secret"])
    assert args.func(args) == 0
    token = capsys.readouterr().out.strip()
    assert re.fullmatch(r"dfrl_[0-9a-f]{64}", token), token
    assert token != new_secret()
    assert SWIPL
    bits = subprocess.run(
        [
            SWIPL,
            "-q",
            "-g",
            f"use_module({str(PLATFORM_DIR / 'node.pl')!r}),"
            f"node:token_entropy_bits('{token}', B), write(B), nl",
            "-t",
            "halt",
        ],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert int(bits.stdout.strip()) >= 128, bits


def test_nonces_are_fresh_and_tokens_never_cross_the_wire(procs: list[Proc]) -> None:
    token = new_secret()
    _, port = start_node(procs, "--port", "0", "--token", token)
    nonces = set()
    for _ in range(20):
        s, nonce = connect_nonce(port)
        assert re.fullmatch(r"[0-9a-f]{32}", nonce), nonce
        nonces.add(nonce)
        s.close()
    assert len(nonces) == 20
    # a whole authenticated exchange, as the bytes the client sent and received
    s, nonce = connect_nonce(port)
    from tests.platform.wire_client import authenticate, token_proof

    verdict = authenticate(s, nonce, token)
    assert verdict.startswith("ok(authenticated)")
    assert token_proof(token, nonce) not in token  # the proof is not the token
    s.close()
