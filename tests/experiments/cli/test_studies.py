"""``dfrl sweep`` and ``dfrl --version`` from the command line."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import dfrl
from dfrl.experiments.cli.studies import parse_factor


def _dfrl(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "dfrl", *args], capture_output=True, text=True,
                          timeout=300)


def test_version() -> None:
    out = _dfrl("--version")
    assert out.returncode == 0 and out.stdout.strip() == f"dfrl {dfrl.__version__}"


def test_factor_syntax() -> None:
    assert parse_factor("learner.alpha=0.1;0.2") == ("learner.alpha", [0.1, 0.2])
    assert parse_factor('learner.epsilon={"kind":"constant"}') == (
        "learner.epsilon", [{"kind": "constant"}])
    assert parse_factor("discretisation.grouping=five") == ("discretisation.grouping", ["five"])


def test_sweep_command_writes_its_table(tmp_path: Path) -> None:
    out = _dfrl("sweep", "--set", "learner.alpha=0.5", "--iterations", "300", "--seeds", "1", "2",
                "--eval-steps", "100", "--held-out", "h1", "--out", str(tmp_path))
    assert out.returncode == 0, out.stderr
    data = json.loads((tmp_path / "sweep.json").read_text())
    assert [d["setting"] for d in data] == ["base", "learner.alpha=0.5"]
    assert len(data[0]["runs"]) == 2
    assert (tmp_path / "sweep.md").read_text().startswith("| setting | score |")
    bad = _dfrl("sweep", "--set", "learner.nope=1", "--iterations", "300", "--seeds", "1")
    assert bad.returncode == 2 and "learner.nope" in bad.stderr
