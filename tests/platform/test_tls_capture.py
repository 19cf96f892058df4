"""Mutual TLS (issue 9): a capture of the bytes between two nodes reveals no token and no
Q-value. A recording proxy sits between node A and node B (two real TLS nodes); an agent
carrying a payload of known floats moves A -> B through it, after A's hello proof of the
token. The control: the same run without TLS, whose capture must show the Q-values.
"""

from __future__ import annotations

import shutil
import struct
from pathlib import Path

import pytest

from dfrl.experiments.tools.bench.fault_proxy import FaultProxy
from dfrl.experiments.tools.certs import init_ca, make_node
from dfrl.platform_pl import PLATFORM_DIR

from .conftest import SWIPL, Proc

pytestmark = pytest.mark.skipif(
    shutil.which("openssl") is None or SWIPL is None, reason="openssl or swipl missing"
)

TOKEN = "tok_capture_5be1c0ffee"
Q_VALUES = [1234.5678901 + i for i in range(50)]

SCRIPT = """
:- use_module({tartarus!r}).
:- dynamic carrier/3, qtable/2.
qtable(guid, {qvalues}).
carrier(guid, (_, _), main) :-
    qtable(guid, Q),
    sum_list(Q, S),
    format("ARRIVED ~w~n", [S]),
    flush_output.
:- initialization(main, main).
main :-
    node_start('127.0.0.1':0, A, [token({token}), default(false){tls_a}]),
    node_start('127.0.0.1':0, B, [token({token}), default(false){tls_b}]),
    node_property(B, address(_:PB)),
    format("PORT ~w~n", [PB]),
    flush_output,
    read_term(user_input, proxy(PP), []),
    with_node(A, ( create_mobile_agent(c1, carrier, [{token}]),
                   add_payload(c1, [(qtable, 2)]),
                   move_agent(c1, ('127.0.0.1', PP)) )),
    read_term(user_input, _, []),
    node_stop(A), node_stop(B).
"""


def _capture(tmp_path: Path, tls: tuple[Path, Path] | None) -> bytes:
    tls_a = f", tls({str(tls[0])!r})" if tls else ""
    tls_b = f", tls({str(tls[1])!r})" if tls else ""
    script = tmp_path / ("tls.pl" if tls else "plain.pl")
    script.write_text(
        SCRIPT.format(
            tartarus=str(PLATFORM_DIR / "tartarus.pl"),
            token=TOKEN,
            qvalues="[" + ", ".join(repr(v) for v in Q_VALUES) + "]",
            tls_a=tls_a,
            tls_b=tls_b,
        )
    )
    assert SWIPL
    proc = Proc([SWIPL, "-q", str(script)])
    try:
        port = int(proc.wait_for("PORT").split()[1])
        proxy = FaultProxy(("127.0.0.1", port), record=True)
        try:
            assert proc.popen.stdin is not None
            proc.popen.stdin.write(f"proxy({proxy.address[1]}).\n")
            proc.popen.stdin.flush()
            arrived = proc.wait_for("ARRIVED", timeout=30)
            assert float(arrived.split()[1]) == pytest.approx(sum(Q_VALUES))
            return proxy.captured_bytes()
        finally:
            proxy.close()
    finally:
        proc.popen.kill()
        proc.popen.wait(timeout=10)


def _leaks(captured: bytes) -> list[str]:
    found = []
    if TOKEN.encode() in captured:
        found.append("token")
    for v in Q_VALUES:
        for enc, name in (
            (repr(v).encode(), "text"),
            (struct.pack("<d", v), "binary-le"),
            (struct.pack(">d", v), "binary-be"),
        ):
            if enc in captured:
                found.append(f"{v} ({name})")
    for marker in (b"DFRL", b"hello(", b"auth("):
        if marker in captured:
            found.append(marker.decode())
    return found


@pytest.fixture(scope="module")
def pki(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    root = tmp_path_factory.mktemp("pki")
    init_ca(root / "ca")
    return make_node("a", root / "ca").directory, make_node("b", root / "ca").directory


def test_tls_capture_reveals_no_token_and_no_q_value(
    tmp_path: Path, pki: tuple[Path, Path]
) -> None:
    captured = _capture(tmp_path, pki)
    assert len(captured) > 8 * len(Q_VALUES)  # the agent did cross the proxy
    assert _leaks(captured) == []


def test_control_plaintext_capture_shows_the_q_values(tmp_path: Path) -> None:
    """The control, which must fail the check above: without TLS the Q-values are there."""
    captured = _capture(tmp_path, None)
    leaks = _leaks(captured)
    assert any("binary" in x or "text" in x for x in leaks), leaks
    assert "DFRL" in leaks and "hello(" in leaks
