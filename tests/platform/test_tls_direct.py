"""TLS records straight to the socket (tls.pl, native/tls_direct.c), over real mutual-TLS
connections on loopback: the plunit cases in tls_direct_cases.pl, run with a CA and a node
certificate made here. Each case has its control in the same file (a connection negotiated
by library(ssl) alone writes through its own stream BIO; a swap asked with streams that are
not the connection's is refused).
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from dfrl.experiments.tools.certs import init_ca, make_node

from .conftest import SWIPL

CASES = Path(__file__).with_name("tls_direct_cases.pl")

pytestmark = pytest.mark.skipif(
    shutil.which("openssl") is None or SWIPL is None, reason="openssl or swipl missing"
)


def test_tls_records_go_straight_to_the_socket(tmp_path: Path) -> None:
    init_ca(tmp_path / "ca")
    make_node("n1", tmp_path / "ca", out=tmp_path / "n1")
    assert SWIPL
    run = subprocess.run(
        [SWIPL, "-g", "run_tests", "-t", "halt", str(CASES)],
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "DFRL_TLS_DIR": str(tmp_path / "n1")},
    )
    out = run.stdout + run.stderr
    assert run.returncode == 0, out[-5000:]
    assert re.search(r"All 7 tests passed", out), out[-5000:]
    assert "Warning" not in out, out[-5000:]
