"""A torn final table (issue 20): a robot killed while it wrote ``tables/r1.npy`` left half a
file. The driver's collection must not crash (``merge_metrics``, the summary), must set the
torn file aside, use the robot's last complete checkpoint instead and say so in
``summary.md``. The results folder comes from a real 2-robot run (real processes); the table
is then torn as a kill mid-write leaves it, and the driver's collection steps run on it.
"""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from dfrl.experiments.driver.launcher import run
from dfrl.experiments.driver.results.metrics import merge_metrics, read_metrics
from dfrl.experiments.driver.results.summary import Results, write_summary
from dfrl.experiments.driver.results.tables import final_tables, table_sum
from dfrl.experiments.robot_host.checkpoint import load_checkpoint
from tests.experiments.driver.launcher.helpers import small_config
from tests.platform.conftest import SWIPL

pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Results]:
    out = tmp_path_factory.mktemp("torn") / "run"
    res = run(small_config(2), out, progress=None)
    assert res.ok, (out / "summary.md").read_text()
    return out, res


def _tear(out: Path, robot: str) -> bytes:
    npy = out / "tables" / f"{robot}.npy"
    whole = npy.read_bytes()
    npy.write_bytes(whole[: len(whole) // 2])
    return whole


def _copy(finished_run: tuple[Path, Results], tmp_path: Path) -> Path:
    out = tmp_path / "run"
    shutil.copytree(finished_run[0], out)
    return out


def test_merge_metrics_survives_a_torn_table(finished_run: tuple[Path, Results],
                                             tmp_path: Path) -> None:
    out = _copy(finished_run, tmp_path)
    _tear(out, "r1")
    assert table_sum(out, "r1") is None
    merge_metrics(out, ["r1", "r2"])
    assert set(read_metrics(out / "metrics.csv")) == {"r1", "r2"}


def test_torn_table_replaced_by_checkpoint_and_reported(finished_run: tuple[Path, Results],
                                                        tmp_path: Path) -> None:
    out = _copy(finished_run, tmp_path)
    _tear(out, "r1")
    r2_before = (out / "tables" / "r2.npy").read_bytes()
    kept, problems = final_tables(out, ["r1", "r2"])
    assert kept == ["r1"]
    assert set(problems) == {"r1"}
    assert "unreadable" in problems["r1"] and "last complete checkpoint" in problems["r1"]
    assert (out / "tables" / "r1.npy.torn").is_file()
    cp = load_checkpoint(out / "checkpoint", "r1")
    assert np.array_equal(np.load(out / "tables" / "r1.npy"), cp.q)
    assert (out / "tables" / "r2.npy").read_bytes() == r2_before
    merge_metrics(out, ["r1", "r2"])
    res = finished_run[1]
    summary = write_summary(Results(out, res.config, res.wall_time_s, res.rounds, {},
                                    res.agents_finished, res.iterations, [], True,
                                    faults=res.faults, from_checkpoint=kept,
                                    table_problems=problems)).read_text()
    assert "TORN TABLE r1" in summary and "tables/r1.npy.torn" in summary
    assert "(last checkpoint)" in summary


def test_whole_tables_are_left_alone(finished_run: tuple[Path, Results], tmp_path: Path) -> None:
    out = _copy(finished_run, tmp_path)
    before = {p.name: p.read_bytes() for p in (out / "tables").glob("*.npy")}
    assert final_tables(out, ["r1", "r2"]) == ([], {})
    assert {p.name: p.read_bytes() for p in (out / "tables").glob("*.npy")} == before
