"""The bridge with the real platform (platform_pl/tartarus.pl), in a process of its own."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = Path(__file__).with_name("platform_script.py")


@pytest.mark.skipif(
    not (ROOT / "platform_pl" / "tartarus.pl").exists(), reason="platform not built"
)
def test_agent_moves_to_robot_node_and_updates_table() -> None:
    proc = subprocess.run(
        [sys.executable, str(SCRIPT)], cwd=ROOT, capture_output=True, text=True, timeout=120
    )
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["done"], out
    assert out["agent"] == out["name"] and out["name"] in out["listed_before"]
    assert out["port_ok"] and out["sum_ok"] and out["table_plus_one"], out
    assert out["left"] == []
    assert out["joined_none"] and out["joined_home"] and out["tartarus_ok"]
    assert out["reload"] == ("refused" if out["spent"] else "ran"), out
    assert out["moved_ok"] and out["purge_ok"] and out["post_ok"], out
    for bad in ("Warning", "ERROR", "Traceback", "Segmentation"):
        assert bad not in proc.stderr, proc.stderr
