"""``dfrl node``: a standalone node from a shell."""
from __future__ import annotations

import subprocess
import sys

import pytest

from dfrl.experiments.cli.node import node_command
from dfrl.experiments.tokens import env_with_tokens

from .conftest import SWIPL, Proc
from .wire_client import request

pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")


def test_node_prints_address_and_serves(procs: list[Proc]) -> None:
    p = Proc([sys.executable, "-m", "experiments", "node", "--port", "0"],
             env=env_with_tokens(["3"]))
    procs.append(p)
    line = p.wait_for("dfrl node listening on")
    port = int(line.rsplit(":", 1)[1])
    assert request(port, "ping").startswith("ok(pong(")


def test_interactive_toplevel_runs_on_the_node() -> None:
    cmd = node_command(port=0, interactive=True)
    run = subprocess.run(
        cmd, input="get_tartarus_details(H, P), format('DETAILS ~w ~w~n', [H, P]).\nhalt.\n",
        capture_output=True, text=True, timeout=60, env=env_with_tokens(["3"]),
    )
    out = run.stdout
    assert "dfrl node listening on localhost:" in out
    port = out.split("dfrl node listening on localhost:")[1].split()[0]
    assert f"DETAILS localhost {port}" in out


def test_out_of_range_port_is_refused() -> None:
    run = subprocess.run([sys.executable, "-m", "experiments", "node", "--port", "70000"],
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 2
    assert "outside 0..65535" in run.stderr
