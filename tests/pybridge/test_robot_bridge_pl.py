"""robot_bridge.pl loads and works in plain swipl (plunit suite test_robot_bridge.pl)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
from dfrl.experiments.processes import find_swipl

SUITE = Path(__file__).with_name("test_robot_bridge.pl")


@pytest.mark.skipif(find_swipl() is None, reason="swipl not installed")
def test_plunit_suite() -> None:
    proc = subprocess.run(
        ["swipl", "-q", "-g", "run_tests", "-t", "halt", str(SUITE)],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "ERROR" not in proc.stderr and "Warning" not in proc.stderr, proc.stderr
