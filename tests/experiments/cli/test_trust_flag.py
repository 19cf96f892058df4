"""``dfrl node --trust NAME`` and ``dfrl robot --trust NAME`` (issue 9): the platform's node option
``trusted_peers(Names)`` from the command line. A TLS peer whose certificate names a trusted
NAME has its agent's code installed without the sandbox check; the same agent from another
certificate name is refused. Real processes, real mutual TLS; ``--trust`` without ``--tls`` or
with a name no certificate can have exits 2 before anything listens.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from dfrl.experiments.tools.certs import init_ca, make_node
from dfrl.platform_pl import PLATFORM_DIR
from tests.platform.conftest import SWIPL, Proc

pytestmark = [
    pytest.mark.skipif(shutil.which("openssl") is None, reason="openssl missing"),
    pytest.mark.skipif(SWIPL is None, reason="swipl not installed"),
]

REPO = Path(__file__).resolve().parents[3]

#: An agent whose handler asserts into ``user``: the sandbox refuses it (a qualified assert).
SENDER = """
:- use_module({tartarus!r}).
:- dynamic marker/3.
marker(guid, _, main) :- assertz(user:marked(guid)), format("MARKED ~w~n", [guid]), flush_output.
main :- node_start(localhost:0, _, [token(9), tls({tls!r})]),
        create_mobile_agent({agent}, marker, [9]),
        catch((move_agent({agent}, (localhost, {port})), R = moved), E, R = E),
        format("RESULT ~q~n", [R]), flush_output.
"""


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A project CA and the TLS folders of ``victim``, ``alpha`` and ``beta``."""
    root = tmp_path_factory.mktemp("pki")
    init_ca(root / "ca")
    return {n: make_node(n, root / "ca", root / n).directory for n in ("victim", "alpha", "beta")}


@pytest.fixture
def procs() -> Iterator[list[Proc]]:
    started: list[Proc] = []
    try:
        yield started
    finally:
        for p in started:
            p.stop()


def _dfrl(*args: str) -> list[str]:
    return [sys.executable, "-m", "dfrl", *args]


def _send(procs: list[Proc], tmp_path: Path, tls: Path, port: int, agent: str) -> str:
    """Move ``agent`` (its code unsafe to the sandbox) from a TLS node with ``tls``'s
    certificate to ``localhost:port``; the sender's ``RESULT`` line."""
    path = tmp_path / f"{agent}.pl"
    path.write_text(
        SENDER.format(
            tartarus=str(PLATFORM_DIR / "tartarus.pl"), tls=str(tls), agent=agent, port=port
        )
    )
    proc = Proc([str(SWIPL), "-q", "-g", "main", "-t", "halt", str(path)])
    procs.append(proc)
    return proc.wait_for("RESULT", timeout=60)


COMMANDS = {
    "node": lambda tls: _dfrl(
        "node",
        "--host",
        "127.0.0.1",
        "--port",
        "0",
        "--token",
        "9",
        "--tls",
        str(tls),
        "--trust",
        "alpha",
    ),
    "robot": lambda tls: _dfrl(
        "robot",
        "--host",
        "127.0.0.1",
        "--port",
        "0",
        "--token",
        "9",
        "--workdir",
        "work",
        "--tls",
        str(tls),
        "--trust",
        "alpha",
    ),
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_trusted_name_installs_unchecked_other_name_refused(
    command: str, tmp_path: Path, pki: dict[str, Path], procs: list[Proc]
) -> None:
    # Prepare: `dfrl node|robot --tls victim --trust alpha` as its own process
    node = Proc(COMMANDS[command](pki["victim"]), cwd=tmp_path)
    procs.append(node)
    port = int(node.wait_for(f"dfrl {command} listening on", timeout=60).rsplit(":", 1)[1])
    # Execute: the same unsafe agent from alpha (trusted) and from beta (not)
    from_alpha = _send(procs, tmp_path, pki["alpha"], port, "from_alpha")
    from_beta = _send(procs, tmp_path, pki["beta"], port, "from_beta")
    # Assert: alpha's agent arrived and its code ran; beta's was refused by the sandbox and the
    # sender was told why
    assert from_alpha == "RESULT moved", node.output()
    node.wait_for("MARKED from_alpha", timeout=30)
    assert "permission_error(install,code,assertz(user:marked(from_beta)))" in from_beta, from_beta
    assert "MARKED from_beta" not in node.output()


@pytest.mark.parametrize("command", ["node", "robot"])
def test_trust_without_tls_exits_2(command: str, tmp_path: Path, pki: dict[str, Path]) -> None:
    base = ["--host", "127.0.0.1", "--port", "0", "--token", "9"]
    for extra, message in (
        (["--trust", "alpha"], "--trust needs --tls"),
        (["--tls", str(pki["victim"]), "--trust", "al pha"], "not a certificate name"),
    ):
        done = subprocess.run(
            _dfrl(command, *base, *extra), cwd=tmp_path, capture_output=True, text=True, timeout=60
        )
        assert done.returncode == 2, done.stdout + done.stderr
        assert f"dfrl {command}: " in done.stderr and message in done.stderr, done.stderr
        assert "listening" not in done.stdout
