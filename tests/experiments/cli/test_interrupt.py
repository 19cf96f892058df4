"""Ctrl-C in ``dfrl run`` stops cleanly: exit 130, says what it kept, tables saved."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from dfrl.experiments.processes import find_swipl

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")


def test_ctrl_c_keeps_tables_and_says_so(tmp_path: Path) -> None:
    # Prepare: a run that lasts long enough (rtf 10: 4000 iterations take ~26 s)
    cfg = {
        "name": "intr",
        "robots": [{"id": "r1", "arena": "r1"}, {"id": "r2", "arena": "r4"}],
        "iterations": 4000,
        "respite": 100,
        "mode": "sync",
        "rtf": 10.0,
        "timeout_s": 120,
    }
    path = tmp_path / "intr.json"
    path.write_text(json.dumps(cfg))
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [sys.executable, "-m", "dfrl", "run", str(path), "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        # Execute: Ctrl-C once the first round is logged
        log = out / "rounds_fed_qlearning.log"
        deadline = time.monotonic() + 90
        while (
            time.monotonic() < deadline
            and proc.poll() is None
            and not (log.is_file() and '"event":"round"' in log.read_text())
        ):
            time.sleep(0.1)
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    # Assert
    assert proc.returncode == 130, stderr
    assert "interrupted" in stderr and "kept in" in stderr and "tables/" in stderr, stderr
    for rid in ("r1", "r2"):
        table = np.load(out / "tables" / f"{rid}.npy")
        assert table.ndim == 2 and np.isfinite(table).all()
    summary = (out / "summary.md").read_text()
    assert "INTERRUPTED" in summary
    assert "no table saved" not in summary
