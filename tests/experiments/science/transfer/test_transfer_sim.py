"""``dfrl transfer-study --sim``: each simulator runs the study end to end on a tiny budget and
records itself; --from-json keeps the file's simulator and refuses another; on the batched
simulator a learning phase and a reference run are the same in any batch."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from dfrl.experiments.cli import main
from dfrl.experiments.science.transfer.batched import learning_phases, reference_levels
from dfrl.experiments.science.transfer.study import StudyOptions, source_job

TINY = [
    "transfer-study",
    "--seeds",
    "1",
    "2",
    "3",
    "--targets",
    "h1",
    "--iterations",
    "40",
    "--respite",
    "20",
    "--learn",
    "40",
    "--eval-every",
    "20",
    "--eval-steps",
    "20",
    "--resamples",
    "200",
    "--jobs",
    "1",
    "--threshold-iterations",
    "40",
    "--threshold-runs",
    "2",
]


@pytest.mark.parametrize("sim", ["batched", "pybullet"])
def test_each_simulator_runs_the_study_and_says_so(
    sim: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / sim
    assert main([*TINY, "--sim", sim, "--out", str(out)]) == 0
    assert f"Simulator: {sim}." in capsys.readouterr().out
    doc = json.loads((out / "transfer_study.json").read_text())
    assert doc["options"]["sim"] == sim
    assert f"Simulator: {sim}." in (out / "transfer_study.md").read_text()
    assert len(doc["rows"]) == 7 * 3  # 7 sources x 3 seeds x h1
    # judged again from the file: its simulator, or refused when told another one
    again = tmp_path / f"{sim}-again"
    assert (
        main(
            [
                "transfer-study",
                "--from-json",
                str(out / "transfer_study.json"),
                "--resamples",
                "200",
                "--out",
                str(again),
            ]
        )
        == 0
    )
    assert json.loads((again / "transfer_study.json").read_text())["options"]["sim"] == sim
    other = "pybullet" if sim == "batched" else "batched"
    assert (
        main(["transfer-study", "--from-json", str(out / "transfer_study.json"), "--sim", other])
        == 2
    )
    assert f"ran on the {sim} simulator, these options ask for {other}" in capsys.readouterr().err


def test_a_file_from_before_sim_is_pybullets(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "b"
    assert main([*TINY, "--threshold", "10", "--out", str(out)]) == 0
    doc = json.loads((out / "transfer_study.json").read_text())
    assert doc["options"]["sim"] == "batched"  # the default
    del doc["options"]["sim"]
    old = tmp_path / "old.json"
    old.write_text(json.dumps(doc))
    assert (
        main(
            [
                "transfer-study",
                "--from-json",
                str(old),
                "--resamples",
                "200",
                "--out",
                str(tmp_path / "judged"),
            ]
        )
        == 0
    )
    judged = json.loads((tmp_path / "judged" / "transfer_study.json").read_text())
    assert judged["options"]["sim"] == "pybullet" and judged["claims"] == doc["claims"]
    assert main(["transfer-study", "--from-json", str(old), "--sim", "batched"]) == 2


def test_a_phase_learns_the_same_in_any_batch() -> None:
    opts = StudyOptions(
        source_seeds=(1, 2),
        targets=("h1", "h2"),
        target_seeds=(1, 2),
        iterations=40,
        respite=20,
        learn=60,
        eval_every=20,
        eval_steps=30,
    )
    srcs = [source_job(c, s, opts) for c in (opts.federated, "zeros") for s in (1, 2)]
    rows = learning_phases(srcs, opts)
    assert len(rows) == 4 * 2 * 2
    alone = learning_phases(srcs[1:2], opts)  # federated, source seed 2
    assert alone == rows[4:8]
    assert [(r["arena"], r["target_seed"]) for r in alone] == [
        ("h1", 1),
        ("h1", 2),
        ("h2", 1),
        ("h2", 2),
    ]
    assert [p for _, p in alone[0]["scores"]] != [p for _, p in alone[1]["scores"]]
    # the zeros source is zeros; the federated one learnt
    assert not srcs[2][2].any() and srcs[0][2].any()
    assert np.array_equal(srcs[0][2], source_job(opts.federated, 1, opts)[2])
    levels = reference_levels([("h1", 1), ("h2", 1), ("h1", 2)], 40, 20, 20)
    assert reference_levels([("h2", 1)], 40, 20, 20) == levels[1:2]
    assert reference_levels([], 40, 20, 20) == []
