"""``dfrl node``: a standalone node from a shell."""

from __future__ import annotations

import subprocess
import sys

import pytest

from dfrl.experiments.cli.node import node_command
from dfrl.experiments.tokens import env_with_tokens
from dfrl.platform_pl import PLATFORM_DIR

from .conftest import SWIPL, Proc
from .wire_client import request

pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")


def test_node_prints_address_and_serves(procs: list[Proc]) -> None:
    p = Proc(
        [sys.executable, "-m", "experiments", "node", "--port", "0"], env=env_with_tokens(["3"])
    )
    procs.append(p)
    line = p.wait_for("dfrl node listening on")
    port = int(line.rsplit(":", 1)[1])
    assert request(port, "ping").startswith("ok(pong(")


def test_interactive_toplevel_runs_on_the_node() -> None:
    cmd = node_command(port=0, interactive=True)
    run = subprocess.run(
        cmd,
        input="get_tartarus_details(H, P), format('DETAILS ~w ~w~n', [H, P]).\nhalt.\n",
        capture_output=True,
        text=True,
        timeout=60,
        env=env_with_tokens(["3"]),
    )
    out = run.stdout
    assert "dfrl node listening on localhost:" in out
    port = out.split("dfrl node listening on localhost:")[1].split()[0]
    assert f"DETAILS localhost {port}" in out


def test_out_of_range_port_is_refused() -> None:
    run = subprocess.run(
        [sys.executable, "-m", "experiments", "node", "--port", "70000"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.returncode == 2
    assert "outside 0..65535" in run.stderr


def _node_options(cmd: list[str], names: list[str]) -> dict[str, str]:
    """Start ``cmd`` (an interactive node) and read back the node options ``names``."""
    query = (
        "current_node(N), forall(member(O, [" + ", ".join(names) + "]), "
        "(node:node_option(N, O, V), format('OPT ~w ~w~n', [O, V]))).\nhalt.\n"
    )
    run = subprocess.run(
        cmd, input=query, capture_output=True, text=True, timeout=60, env=env_with_tokens(["3"])
    )
    return dict(line.split()[1:3] for line in run.stdout.splitlines() if line.startswith("OPT "))


def test_bound_flags_reach_the_node() -> None:
    bounds = {
        "agent_cpu_limit": 0.5,
        "agent_stack_limit": 134217728,
        "agent_module_limit": "infinite",
        "agent_post_limit": 7,
        "agent_log_limit": 9,
        "max_agents": 3,
        "clone_limit": 4,
        "agent_memory_budget": 536870912,
        "max_running_agents": 2,
        "agent_slot_wait": 5,
        "max_frame_size": 1048576,
        "agent_wall_limit": 7.5,
        "agent_idle_limit": "infinite",
        "max_agents_per_peer": 6,
        "max_running_per_peer": 2,
        "peer_post_limit": 100,
    }
    cmd = node_command(port=0, interactive=True, bounds=bounds)
    got = _node_options(cmd, list(bounds))
    assert got == {k: str(v) for k, v in bounds.items()}, got
    # without the flags: the defaults
    got = _node_options(
        node_command(port=0, interactive=True),
        [
            "agent_memory_budget",
            "max_running_agents",
            "max_frame_size",
            "agent_wall_limit",
            "agent_idle_limit",
            "max_agents_per_peer",
            "max_running_per_peer",
            "peer_post_limit",
        ],
    )
    assert got == {
        "agent_memory_budget": "1073741824",
        "max_running_agents": "8",
        "max_frame_size": "33554432",
        "agent_wall_limit": "60",
        "agent_idle_limit": "600",
        "max_agents_per_peer": "50",
        "max_running_per_peer": "4",
        "peer_post_limit": "6000",
    }


@pytest.mark.parametrize(
    "flag, value",
    [
        ("--max-agents", "0"),
        ("--agent-cpu-limit", "fast"),
        ("--agent-stack-limit", "1.5"),
        ("--agent-memory-budget", "-1"),
        ("--max-frame-size", "infinite"),
        ("--agent-slot-wait", "infinite"),
        ("--agent-wall-limit", "0"),
        ("--agent-idle-limit", "soon"),
        ("--max-agents-per-peer", "2.5"),
        ("--max-running-per-peer", "-1"),
        ("--peer-post-limit", "0"),
    ],
)
def test_bad_bound_exits_2_naming_the_flag(flag: str, value: str) -> None:
    run = subprocess.run(
        [sys.executable, "-m", "experiments", "node", "--port", "0", flag, value],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.returncode == 2 and flag in run.stderr, run.stderr
    assert SWIPL
    run = subprocess.run(
        [SWIPL, str(PLATFORM_DIR / "node_main.pl"), "--port", "0", flag, value],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert run.returncode == 2 and f"{flag} needs a positive" in run.stderr, run.stderr


def test_node_command_refuses_a_bad_bound() -> None:
    with pytest.raises(ValueError, match="--max-agents"):
        node_command(bounds={"max_agents": 0})
    with pytest.raises(ValueError, match="unknown bound"):
        node_command(bounds={"max_agent": 3})
