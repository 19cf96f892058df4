"""``dfrl speedup --sim``: each simulator runs the study end to end on a tiny budget and
records itself; a study's runs file never mixes them (a resume or a run into it with the other
one is refused), and a runs file written before --sim counts as pybullet's."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from dfrl.experiments.cli import main

ARGS = [
    "speedup",
    "--robots",
    "1",
    "2",
    "--n-seeds",
    "3",
    "--iterations",
    "200",
    "--budget",
    "1=200",
    "--share-every",
    "100",
    "--grid",
    "100",
    "--score-every",
    "200",
    "--eval-steps",
    "50",
    "--targets",
    "0.999",
    "0.2",
    "--resamples",
    "200",
    "--jobs",
    "1",
]


def recorded(out: Path) -> tuple[str, set[str]]:
    """The simulator of speedup.json's options and those of the runs file's recipes."""
    data = json.loads((out / "speedup.json").read_text())
    lines = (out / "speedup_runs.jsonl").read_text().splitlines()
    return data["options"]["sim"], {json.loads(line)["recipe"]["sim"] for line in lines}


@pytest.mark.parametrize("sim", ["batched", "pybullet"])
def test_each_simulator_runs_the_study_and_says_so(
    sim: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / sim
    assert main([*ARGS, "--sim", sim, "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"Speed-up against the number of robots ({sim} simulator)" in text
    assert "| error<=0.999 | 2 | 1xr1+1xr2 | 3/3 | 100 [100, 100]" in text
    assert recorded(out) == (sim, {sim})
    # the other simulator is refused, resumed or appended, and nothing is added
    other = "pybullet" if sim == "batched" else "batched"
    runs = (out / "speedup_runs.jsonl").read_text()
    for extra in (["--resume"], []):
        assert main([*ARGS, "--sim", other, "--out", str(out), *extra]) == 2
        err = capsys.readouterr().err
        assert (
            f"speedup_runs.jsonl:1: ran on the {sim} simulator, these options ask for "
            f"{other}; one study does not mix simulators" in err
        )
        assert (out / "speedup_runs.jsonl").read_text() == runs
    assert main([*ARGS, "--sim", other, "--from-runs", str(out / "speedup_runs.jsonl")]) == 2
    assert "does not mix simulators" in capsys.readouterr().err


def test_the_default_is_batched_and_old_runs_are_pybullet(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "default"
    assert main([*ARGS, "--out", str(out)]) == 0
    assert recorded(out) == ("batched", {"batched"})
    # a runs file of before --sim (no "sim" in its recipes) ran on pybullet: resumed as such,
    # nothing run again; refused to the batched simulator
    old = tmp_path / "old"
    old.mkdir()
    lines = []
    for line in (out / "speedup_runs.jsonl").read_text().splitlines():
        r = json.loads(line)
        del r["recipe"]["sim"]
        lines.append(json.dumps(r))
    (old / "speedup_runs.jsonl").write_text("\n".join(lines) + "\n")
    capsys.readouterr()
    assert main([*ARGS, "--sim", "pybullet", "--out", str(old), "--resume"]) == 0
    assert "[" not in capsys.readouterr().err  # no federation run
    assert len((old / "speedup_runs.jsonl").read_text().splitlines()) == 9
    assert json.loads((old / "speedup.json").read_text())["options"]["sim"] == "pybullet"
    assert main([*ARGS, "--out", str(old), "--resume"]) == 2
    assert "ran on the pybullet simulator, these options ask for batched" in capsys.readouterr().err
