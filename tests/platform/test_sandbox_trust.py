"""Trust by name (issue 9): a node with ``trusted_peers(Names)`` installs, unchecked, the code
of a TLS peer whose certificate names one of them; any other peer's code goes through the
sandbox. Real processes, real mutual TLS handshakes.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from dfrl.experiments.tools.certs import init_ca, make_node
from dfrl.platform_pl import PLATFORM_DIR

from . import hostile_node
from .conftest import SWIPL, Proc

pytestmark = [
    pytest.mark.skipif(shutil.which("openssl") is None, reason="openssl missing"),
    pytest.mark.skipif(SWIPL is None, reason="swipl not installed"),
]


def sender(procs: list[Proc], tmp_path: Path, tls: Path, port: int, name: str) -> Proc:
    """A TLS console that moves an agent whose code the sandbox refuses (a qualified assert)."""
    prog = f"""
    :- use_module({str(PLATFORM_DIR / "tartarus.pl")!r}).
    :- dynamic marker/3.
    marker(guid, _, main) :- assertz(user:marked(guid)), format("MARKED ~w~n", [guid]), flush_output.
    main :- node_start(localhost:0, _, [token(9), tls({str(tls)!r})]),
            create_mobile_agent({name}, marker, [9]),
            catch((move_agent({name}, (localhost, {port})), R = moved), E, R = E),
            format("RESULT ~q~n", [R]), flush_output.
    """
    path = tmp_path / f"{name}.pl"
    path.write_text(prog)
    proc = Proc([SWIPL, "-q", "-g", "main", "-t", "halt", str(path)])
    procs.append(proc)
    return proc


def test_trusted_peer_code_installed_unchecked(tmp_path: Path, procs: list[Proc]) -> None:
    # Prepare: a CA, the node "victim" trusting "alpha", senders alpha and beta.
    init_ca(tmp_path / "ca")
    dirs = {n: make_node(n, tmp_path / "ca").directory for n in ("victim", "alpha", "beta")}
    node, port = hostile_node.start(
        procs, tmp_path, f"[token(9), tls({str(dirs['victim'])!r}), trusted_peers([alpha])]"
    )
    # Execute
    alpha = sender(procs, tmp_path, dirs["alpha"], port, "from_alpha")
    beta = sender(procs, tmp_path, dirs["beta"], port, "from_beta")
    # Assert: alpha's agent arrived and ran its (unsafe to others) code; beta's was refused.
    assert alpha.wait_for("RESULT") == "RESULT moved"
    node.wait_for("MARKED from_alpha")
    refused = beta.wait_for("RESULT")
    assert "permission_error(install,code,assertz(user:marked(from_beta)))" in refused
    assert "MARKED from_beta" not in node.output()
