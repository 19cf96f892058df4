"""Control and listing need authentication (issue 9): the hijack chain fails at its first step.

The chain: an unauthenticated peer posts ``dfrl_control`` ``join(stop(...))`` to the agent's
first stop, the agent migrates to the attacker with its tokens, the attacker loads a shell
command with them. Here the first post is refused, as are listings, migration status and
posts to agents, unless the peer proved a token; with a proof they are served.
"""

from __future__ import annotations

from pathlib import Path

from dfrl.platform_pl import PLATFORM_DIR

from . import hostile_node
from .conftest import Proc
from .wire_client import request

TOKEN = "9"


def _node(procs: list[Proc], tmp_path: Path) -> int:
    _, port = hostile_node.start(
        procs,
        tmp_path,
        f"[token({TOKEN})]",
        consult=(PLATFORM_DIR / "dfrl_agent" / "dfrl_agent.pl",),
    )
    return port


def test_hijack_chain_fails_at_its_first_step(tmp_path: Path, procs: list[Proc]) -> None:
    port = _node(procs, tmp_path)
    join = "post(platform, dfrl_control, x, [fx, join(stop('127.0.0.1', 1, evil))])"
    # the attacker's post is refused before anything is queued
    assert "permission_error(request,platform," in request(port, join)
    # a peer that proved the token is served (the event is declared by dfrl_agent)
    assert request(port, join, token=TOKEN).startswith("ok(delivered)")


def test_listing_status_and_posts_need_a_proof(tmp_path: Path, procs: list[Proc]) -> None:
    port = _node(procs, tmp_path)
    for req in ("agents", "migration_status(m1)", "custody_agents", "post(nobody, hello, x, [])"):
        assert "permission_error(request,platform," in request(port, req), req
    assert request(port, "agents", token=TOKEN).startswith("ok(")
    assert request(port, "migration_status(m1)", token=TOKEN).startswith("ok(unknown(")
    assert "existence_error(agent,nobody)" in request(
        port, "post(nobody, hello, x, [])", token=TOKEN
    )
    # ping stays public; a wrong token proves nothing
    assert request(port, "ping").startswith("ok(pong(")
    try:
        request(port, "agents", token="10")
    except AssertionError as e:
        assert "permission_error(authenticate" in str(e)
    else:
        raise AssertionError("a wrong token was accepted")
