"""A migration, captured on the wire, reveals no token (issue 9).

A recording proxy stands between the source (a console process) and the
destination node; every byte of the hand-over in both directions is kept, and
the token string must not occur in them, while the agent's payload does (the
capture did see the record).
"""

from __future__ import annotations

from pathlib import Path

import pytest

from dfrl.experiments.tools.bench.fault_proxy import FaultProxy
from dfrl.platform_pl import PLATFORM_DIR

from .conftest import SWIPL, Proc, start_node

pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")

TOKEN = "dfrl_" + "5e" * 32  # a strong token: no loopback warning, easy to find


def test_migration_sends_no_token(tmp_path: Path, procs: list[Proc]) -> None:
    # Prepare: a node with the token, a recording proxy in front of it.
    node, port = start_node(procs, "--token", TOKEN)
    with FaultProxy(("127.0.0.1", port), record=True) as proxy:
        pport = proxy.address[1]
        prog = f"""
        :- use_module({str(PLATFORM_DIR / "tartarus.pl")!r}).
        :- dynamic courier/3, parcel/2.
        parcel(guid, payload_marker_0451).
        courier(guid, (_, P), main) :- parcel(guid, X),
            format("COURIER ~w at ~w~n", [X, P]), flush_output.
        main :- node_start(localhost:0, _, [token({TOKEN!r})]),
                create_mobile_agent(c1, courier, [{TOKEN!r}]),
                add_payload(c1, [(parcel, 2)]),
                move_agent(c1, (localhost, {pport})),
                format("MOVED~n"), flush_output.
        """
        path = tmp_path / "console.pl"
        path.write_text(prog)
        console = Proc([SWIPL, "-q", "-g", "main", "-t", "halt", str(path)])
        procs.append(console)
        # Execute
        console.wait_for("MOVED")
        node.wait_for("COURIER payload_marker_0451")
        captured = proxy.captured_bytes()
    # Assert: the record crossed, the token did not.
    assert b"payload_marker_0451" in captured
    assert TOKEN.encode() not in captured
    assert b"5e5e5e5e5e5e5e5e" not in captured
