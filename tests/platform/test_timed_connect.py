"""A connect to a host whose link is cut gives up within its time limit in a Prolog that runs
without signals, as a robot process's does (pyswip starts it with ``--nosignals``).

Two namespaces made by the test: ``b`` listens, then its link is cut; ``swipl --no-signals`` in
``a`` connects with a 2 s limit. ``timed_connect/4`` (what the platform's transport uses) must
give up with ``time_limit_exceeded`` in about 2 s. The control, the transport's former way
(``call_with_time_limit/2`` around ``tcp_connect/3``), must still be blocked after 8 s: the
alarm cannot interrupt the connect without signals. Before the cut both connect.
"""

from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from dfrl.experiments.processes import find_swipl
from dfrl.experiments.tools.netns import REPO_ROOT, Lab, unavailable

WHY = unavailable() or (None if find_swipl() else "needs swipl")
pytestmark = pytest.mark.skipif(WHY is not None, reason=WHY or "")

PORT = 7555
SCRIPT = f"""
:- use_module('{REPO_ROOT / "platform_pl" / "timed_connect"}').
:- use_module(library(socket)).
:- use_module(library(time)).
timed(Addr) :- timed_connect(Addr, P, 2, [nodelay(true)]), close(P).
alarm(Addr) :- call_with_time_limit(2, tcp_connect(Addr, P, [])), close(P).
main :- current_prolog_flag(argv, [H, Which|_]), G =.. [Which, H:{PORT}],
    get_time(T0), catch((G, R = ok), E, R = E), get_time(T1), D is T1 - T0,
    format("~q ~3f~n", [R, D]).
"""


def connect(lab: Lab, script: Path, which: str, timeout: float) -> tuple[str, float] | None:
    """(outcome, seconds) of one connect from ``a`` to ``b``; None if still blocked after
    ``timeout`` seconds."""
    argv = [
        find_swipl(),
        "-q",
        "--no-signals",
        "-g",
        "main",
        "-t",
        "halt",
        str(script),
        lab["b"].address,
        which,
    ]
    try:
        done = lab["a"].run(argv, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return None
    m = re.match(r"(.*) ([0-9.]+)$", done.stdout.strip())
    assert m, done.stdout + done.stderr
    return m.group(1), float(m.group(2))


def test_a_cut_host_costs_the_connect_its_time_limit_only(tmp_path: Path) -> None:
    script = tmp_path / "connect.pl"
    script.write_text(SCRIPT, encoding="utf-8")
    with Lab(["a", "b"]) as lab:
        lab["b"].popen(
            [
                sys.executable,
                "-c",
                "import socket, time; s = socket.socket(); "
                f"s.bind(('0.0.0.0', {PORT})); s.listen(50); time.sleep(120)",
            ]
        )
        deadline = time.monotonic() + 10  # until b's listener is up
        got = connect(lab, script, "timed", 10)
        while (got is None or got[0] != "ok") and time.monotonic() < deadline:
            time.sleep(0.2)
            got = connect(lab, script, "timed", 10)
        assert got is not None and got[0] == "ok", got
        assert connect(lab, script, "alarm", 10)[0] == "ok"
        lab.cut("b")
        timed = connect(lab, script, "timed", 15)
        assert timed is not None and timed[0] == "time_limit_exceeded", timed
        assert 1.9 <= timed[1] < 4.0, timed
        assert connect(lab, script, "alarm", 8) is None  # control: blocked past its limit
