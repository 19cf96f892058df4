"""The driver's collection of a function learner's final parameters (``params/<robot>.npy``):
the sum the summary and metrics use, a torn file set aside, the last checkpoint used instead
(hand-made files, no processes)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from dfrl.experiments.driver.results.tables import final_tables, learnt_path, table_sum
from dfrl.experiments.robot_host.checkpoint import Checkpoint, save_checkpoint


def _checkpoint(out: Path, robot: str, vec: np.ndarray, iteration: int) -> None:
    save_checkpoint(out / "checkpoint", robot,
                    Checkpoint(q=None, visits=None, params=vec, iteration=iteration, shares=3))


def test_torn_params_replaced_by_the_checkpoint(tmp_path: Path) -> None:
    # Prepare: r1's final parameters torn, r2's whole, r3 wrote none; all have a checkpoint
    vec = np.array([0.5, -1.0, 2.25])
    (tmp_path / "params").mkdir()
    whole = tmp_path / "params" / "r2.npy"
    np.save(whole, vec * 2)
    np.save(tmp_path / "params" / "r1.npy", vec)
    torn = (tmp_path / "params" / "r1.npy").read_bytes()
    (tmp_path / "params" / "r1.npy").write_bytes(torn[: len(torn) - 5])
    for rid in ("r1", "r2", "r3"):
        _checkpoint(tmp_path, rid, vec, 300)
    # Execute
    kept, problems = final_tables(tmp_path, ["r1", "r2", "r3"])
    # Assert: r1 and r3 from their checkpoints, r2 untouched; nothing went to tables/
    assert kept == ["r1", "r3"] and list(problems) == ["r1"]
    assert "params/r1.npy unreadable" in problems["r1"]
    assert "set aside as params/r1.npy.torn" in problems["r1"]
    assert "its last complete checkpoint is used (iteration 300)" in problems["r1"]
    assert (tmp_path / "params" / "r1.npy.torn").is_file()
    for rid in ("r1", "r3"):
        assert np.array_equal(np.load(tmp_path / "params" / f"{rid}.npy"), vec)
        doc = json.loads((tmp_path / "params" / f"{rid}.json").read_text())
        assert doc["iteration"] == 300 and doc["shape"] == [3]
        assert "final parameters" in doc["source"]
    assert np.array_equal(np.load(whole), vec * 2)
    assert table_sum(tmp_path, "r2") == 3.5 and table_sum(tmp_path, "r1") == 1.75
    assert learnt_path(tmp_path, "r2") == whole and learnt_path(tmp_path, "r4") is None
    assert not (tmp_path / "tables").exists()
