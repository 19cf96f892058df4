"""``dfrl bench sim-fidelity`` end to end at a tiny budget (real pybullet and batched runs)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from tests.robots.batched.made_arena import make_arena


def _bench(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "dfrl.experiments", "bench", "sim-fidelity", *args],
        capture_output=True,
        text=True,
        timeout=600,
    )


def test_the_report_says_each_check_and_its_verdict(tmp_path: Path) -> None:
    arena = str(make_arena(tmp_path / "made.json", seed=4))
    r = _bench(
        "--arenas",
        arena,
        "--poses",
        "100",
        "--transitions",
        "400",
        "--policy-steps",
        "2000",
        "--n-seeds",
        "2",
        "--tables",
        "1",
        "--iterations",
        "300",
        "--eval-steps",
        "200",
        "--workers",
        "1",
        "--json",
        "--out",
        str(tmp_path / "out"),
    )
    assert r.returncode in (0, 1), r.stderr
    out = json.loads(r.stdout)
    a = out["arenas"][arena]
    assert set(a["within_tolerance"]) == {"sensing", "transitions", "policies", "learning"}
    assert a["sensing"]["state_agreement"] > 0.9
    learning = a["learning"]
    assert learning["tables_per_seed"] == 1 and len(learning["per_seed"]) == 2
    # two seeds of one table each cannot certify a 0.05 margin: the check must say so
    assert learning["half_width"] > 0.05 and not learning["holds"]
    assert r.returncode == 1 and out["holds"] is False
    assert a["affects"], "a check out of tolerance names what it affects"
    md = (tmp_path / "out" / "fidelity.md").read_text(encoding="utf-8")
    assert "does NOT hold" in md and "IR readings" in md


def test_a_bad_arena_or_budget_is_a_clear_error() -> None:
    r = _bench("--arenas", "nowhere.json")
    assert r.returncode == 2 and "nowhere.json: cannot read arena file" in r.stderr
    r = _bench("--n-seeds", "1")
    assert r.returncode == 2 and "seeds >= 2" in r.stderr
