"""``--tensorboard``: a tiny real run (two robot processes, an agent, live evaluations) and a
``dfrl train`` write event files whose scalars are the values of their CSV files, read back
from the TFRecord frames (both CRC-32C sums checked) with tensorboardX's protobuf classes.
Controls: the same reading against the other robot's CSV rows fails; a flipped byte is a
located error; without tensorboardX the flag is refused before anything starts."""
from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import pytest

pytest.importorskip("tensorboardX")

from dfrl.experiments.cli import main  # noqa: E402
from dfrl.experiments.driver.results.tensorboard import (TENSORBOARD_DIR, TRAIN_TAGS,  # noqa: E402
                                                        read_scalars)
from dfrl.experiments.processes import find_swipl  # noqa: E402
from dfrl.robots.td import EpsilonSchedule  # noqa: E402


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _curve(rows: list[dict[str, str]], robot: str, column: str) -> list[tuple[int, float]]:
    return [(int(r["iteration"]), float(r[column])) for r in rows if r["robot"] == robot]


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``dfrl run --tensorboard`` of two robots, 300 iterations, a share every 100, live
    evaluations every 150 iterations, an exploration schedule of its own."""
    if find_swipl() is None:
        pytest.skip("needs swipl")
    tmp = tmp_path_factory.mktemp("tb")
    cfg = {"name": "tb", "robots": [{"id": "r1", "arena": "r1"}, {"id": "r2", "arena": "r4"}],
           "iterations": 300, "respite": 100, "seed": 3, "mode": "sync", "timeout_s": 120,
           "eval_every": 150, "eval_steps": 50,
           "trainer": {"learner": {"epsilon": {"kind": "linear", "start": 0.5, "end": 0.1,
                                               "decay_steps": 200}}}}
    path = tmp / "tb.json"
    path.write_text(json.dumps(cfg), encoding="utf-8")
    out = tmp / "run"
    assert main(["run", str(path), "--out", str(out), "--tensorboard",
                 "--figure-format", "png"]) == 0, (out / "summary.md").read_text()
    return out


def test_run_scalars_equal_the_csv_files(run_folder: Path) -> None:
    metrics = _rows(run_folder / "metrics.csv")
    evals = _rows(run_folder / "live_evaluations.csv")
    schedule = EpsilonSchedule(kind="linear", start=0.5, end=0.1, decay_steps=200)
    for robot in ("r1", "r2"):
        got = read_scalars(run_folder / TENSORBOARD_DIR / robot)
        for column in ("q_sum", "cumulative_reward", "collisions"):
            want = _curve(metrics, robot, column)
            assert len(want) >= 300 and got[column] == want, (robot, column)
        its = [it for it, _ in _curve(metrics, robot, "q_sum")]
        assert got["epsilon"] == [(it, schedule.value(it)) for it in its]
        assert got["epsilon"][-1][1] == pytest.approx(0.1)    # the schedule, not the default's 0.02
        arena = "r1" if robot == "r1" else "r4"
        for m in ("collisions_per_1000", "progress", "coverage", "distance", "mean_reward"):
            assert got[f"eval/{arena}/{m}"] == _curve(evals, robot, m), (robot, m)
        assert [it for it, _ in got[f"eval/{arena}/progress"]] == [150, 300]
        shares = _rows(run_folder / f"shares_{robot}.csv")
        assert got["shares"] == [(int(s["iteration"]), float(n))
                                 for n, s in enumerate(shares, start=1)]
        assert [it for it, _ in got["shares"]] == [100, 200, 300]
    rounds = _rows(run_folder / "rounds.csv")
    agents = sorted({r["agent"] for r in rounds})
    assert sorted(p.name for p in (run_folder / TENSORBOARD_DIR).iterdir()) == \
        ["r1", "r2"] + [f"round_{a}" for a in agents]
    got = read_scalars(run_folder / TENSORBOARD_DIR / f"round_{agents[0]}")
    mine = [r for r in rounds if r["agent"] == agents[0]]
    assert got["duration_ms"] == [(int(r["round"]), float(r["duration_ms"])) for r in mine]
    assert got["bytes"] == [(int(r["round"]), float(r["bytes"])) for r in mine]
    assert got["all_equal"] == [(int(r["round"]), 1.0) for r in mine]
    assert got["visited"] == [(int(r["round"]), 2.0) for r in mine]


def test_control_the_comparison_can_fail(run_folder: Path) -> None:
    """The same reading against the other robot's rows differs (the two robots learnt in
    different arenas), so the equality above is not true of any two curves."""
    metrics = _rows(run_folder / "metrics.csv")
    got = read_scalars(run_folder / TENSORBOARD_DIR / "r1")
    assert got["q_sum"] != _curve(metrics, "r2", "q_sum")
    assert got["cumulative_reward"] != _curve(metrics, "r2", "cumulative_reward")


def test_collect_writes_the_same_scalars(run_folder: Path, tmp_path: Path) -> None:
    """``dfrl collect --tensorboard`` on the run's folder (its TensorBoard files removed)
    writes the scalars again, equal to those the run wrote."""
    import shutil

    copy = tmp_path / "run"
    shutil.copytree(run_folder, copy)
    shutil.rmtree(copy / TENSORBOARD_DIR)
    assert main(["collect", str(copy), "--wait", "0", "--tensorboard"]) == 0
    for robot in ("r1", "r2"):
        assert read_scalars(copy / TENSORBOARD_DIR / robot) == \
            read_scalars(run_folder / TENSORBOARD_DIR / robot), robot
    # control: without the flag none are written
    shutil.rmtree(copy / TENSORBOARD_DIR)
    assert main(["collect", str(copy), "--wait", "0"]) == 0
    assert not (copy / TENSORBOARD_DIR).exists()


def test_a_damaged_event_file_is_a_located_error(run_folder: Path, tmp_path: Path) -> None:
    [src] = list((run_folder / TENSORBOARD_DIR / "r1").glob("events.out.tfevents.*"))
    data = bytearray(src.read_bytes())
    data[len(data) // 2] ^= 0x01
    bad = tmp_path / src.name
    bad.write_bytes(bytes(data))
    with pytest.raises(ValueError, match="checksum at byte"):
        read_scalars(tmp_path)
    bad.write_bytes(src.read_bytes()[:-3])
    with pytest.raises(ValueError, match="torn record"):
        read_scalars(tmp_path)


def test_train_scalars_equal_its_metrics(tmp_path: Path) -> None:
    out = tmp_path / "train"
    assert main(["train", "--arena", "r1", "--iterations", "200", "--seed", "2", "--out",
                 str(out), "--no-progress", "--no-plot", "--tensorboard"]) == 0
    rows = _rows(out / "metrics.csv")
    got = read_scalars(out / TENSORBOARD_DIR)
    assert sorted(got) == sorted(TRAIN_TAGS)
    for tag in TRAIN_TAGS:
        assert got[tag] == [(int(r["iteration"]), float(r[tag])) for r in rows], tag
    assert got["epsilon"][0][1] > got["epsilon"][-1][1]       # the recorded schedule decays


def test_without_tensorboardx_the_flag_is_refused_before_anything_starts(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> None:
    monkeypatch.setitem(sys.modules, "tensorboardX", None)       # import fails as if absent
    out = tmp_path / "train"
    with pytest.raises(SystemExit) as exit_:
        main(["train", "--arena", "r1", "--iterations", "50", "--out", str(out),
              "--tensorboard"])
    assert exit_.value.code == 2
    err = capsys.readouterr().err
    assert "pip install 'dfrl[tensorboard]'" in err and "nothing was started" in err
    assert not out.exists()
    # the control: the same command without the flag runs
    assert main(["train", "--arena", "r1", "--iterations", "50", "--out", str(out),
                 "--no-progress", "--no-plot"]) == 0
    assert (out / "metrics.csv").is_file() and not (out / TENSORBOARD_DIR).exists()
