"""Transfer experiment: smoke test of ``dfrl transfer``, shape checks, determinism."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from dfrl.experiments.cli import main
from dfrl.experiments.science.transfer import (
    METRICS,
    RunResult,
    TransferConfig,
    aggregate,
    run,
    summarise,
)
from dfrl.robots.tables import TableMeta, load_table, save_table
from dfrl.robots.training import TrainerConfig, train

#: An L-shaped room (a big block fills one corner) with five small pillars: none of r1..r5.
L_ARENA = {
    "name": "l6_test",
    "description": "L-shaped room with five pillars (test arena, not used in training)",
    "size": [1.2, 1.0],
    "wall_height": 0.1,
    "blocks": [
        {"center": [0.35, 0.3], "size": [0.5, 0.4, 0.1]},
        {"center": [-0.3, 0.25], "size": [0.08, 0.08, 0.1]},
        {"center": [-0.3, -0.2], "size": [0.08, 0.08, 0.1], "yaw": 0.7854},
        {"center": [0.0, -0.05], "size": [0.08, 0.08, 0.1]},
        {"center": [0.3, -0.25], "size": [0.08, 0.08, 0.1]},
        {"center": [-0.05, 0.3], "size": [0.08, 0.08, 0.1]},
    ],
    "start": {"pose": [-0.45, -0.4, 0.0]},
}


@pytest.fixture(scope="module")
def setup(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """A tiny standalone table trained in r1, and the L arena file."""
    tmp = tmp_path_factory.mktemp("transfer")
    arena = tmp / "l6_test.json"
    arena.write_text(json.dumps(L_ARENA), encoding="utf-8")
    train(TrainerConfig(arena="r1", algo="qlearning", seed=1, iterations=300), tmp / "r1")
    return tmp / "r1" / "q_table.npy", arena


def test_command_json_output_and_files(
    setup: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # Prepare
    table, arena = setup
    out = tmp_path / "out"
    # Execute
    rc = main(
        [
            "transfer",
            "--init",
            str(table),
            "--arena",
            str(arena),
            "--iterations",
            "150",
            "--seeds",
            "1",
            "2",
            "--eval-steps",
            "100",
            "--jobs",
            "1",
            "--out",
            str(out),
            "--json",
        ]
    )
    # Assert
    assert rc == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["arena"] == "l6_test" and doc["same_arena"] is False
    assert doc["table"]["algo"] == "qlearning" and doc["table"]["arena"] == "r1"
    assert doc["trainer_config"]["arena"] == str(arena)
    assert doc["trainer_config"]["iterations"] == 150
    assert [(r["seed"], r["condition"]) for r in doc["runs"]] == [
        (1, "init"),
        (1, "zero"),
        (2, "init"),
        (2, "zero"),
    ]
    for r in doc["runs"]:
        assert r["iterations"] == 150 and r["head_steps"] == 150 and r["head10_steps"] == 15
        assert r["collisions_per_1000"] == pytest.approx(1000 * r["collisions"] / 150)
        assert r["mean_reward"] == pytest.approx(r["cumulative_reward"] / 150)
        assert r["eval_collisions_per_1000"] is not None
        assert r["initial_eval_mean_reward"] is not None
    for cond in ("init", "zero"):
        assert set(doc["summary"][cond]) == set(METRICS)
        assert doc["summary"][cond]["cumulative_reward"]["n"] == 2
    assert set(doc["ratio"]) == set(METRICS)
    for name in ("config.json", "provenance.json", "runs.csv", "curves.csv", "summary.json"):
        assert (out / name).exists(), name
    made_by = json.loads((out / "provenance.json").read_text(encoding="utf-8"))
    assert made_by["numpy"] == np.__version__ and isinstance(made_by["command"], list)
    assert (out / "transfer.png").stat().st_size > 10_000
    with open(out / "runs.csv", newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 4 and list(rows[0]) == list(RunResult.CSV_FIELDS)
    cfg = json.loads((out / "config.json").read_text(encoding="utf-8"))
    assert cfg["transfer"]["seeds"] == [1, 2] and cfg["trainer"]["algo"] == "qlearning"


def test_command_readable_table(
    setup: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    table, arena = setup
    rc = main(
        [
            "transfer",
            "--init",
            str(table),
            "--arena",
            str(arena),
            "--iterations",
            "100",
            "--seed",
            "1",
            "--eval-steps",
            "0",
            "--algo",
            "sarsa",
            "--jobs",
            "1",
        ]
    )
    text = capsys.readouterr().out
    assert rc == 0
    assert "into l6_test: sarsa, 100 iterations x 1 seeds" in text
    assert "collisions/1000, first 100 steps" in text and "init/zero" in text
    assert "greedy eval reward per step, before" in text


def test_same_seeds_give_identical_results(setup: tuple[Path, Path]) -> None:
    table, arena = setup
    cfg = TransferConfig(
        init=str(table), arena=str(arena), iterations=120, seeds=(3, 4), eval_steps=60, jobs=1
    )
    a = run(cfg)
    b = run(TransferConfig(**{**cfg.to_dict(), "seeds": (3, 4), "jobs": 2}))
    for ra, rb in zip(a.runs, b.runs):
        sa, sb = ra.scalars(), rb.scalars()
        sa.pop("wall_time"), sb.pop("wall_time")
        assert sa == sb
        np.testing.assert_array_equal(ra.curve_collisions, rb.curve_collisions)
        np.testing.assert_array_equal(ra.curve_reward, rb.curve_reward)
    # the two conditions really start differently
    init, zero = a.runs[0], a.runs[1]
    assert (init.cumulative_reward, init.collisions) != (
        zero.cumulative_reward,
        zero.collisions,
    ) or init.initial_eval_collisions_per_1000 != zero.initial_eval_collisions_per_1000


def test_mismatched_levels_give_a_clear_error(
    setup: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    table, arena = setup
    rc = main(
        [
            "transfer",
            "--init",
            str(table),
            "--arena",
            str(arena),
            "--iterations",
            "10",
            "--seed",
            "1",
            "--levels",
            "2",
        ]
    )
    err = capsys.readouterr().err
    assert rc == 2
    assert "table shape (81, 3) does not fit the trainer" in err
    assert "'four' x 2 levels = 16 states" in err and "need shape (16, 3)" in err


def test_bare_table_of_the_wrong_shape(tmp_path: Path, setup: tuple[Path, Path]) -> None:
    _, arena = setup
    bare = tmp_path / "bare.npy"
    np.save(bare, np.zeros((27, 3)))
    with pytest.raises(
        ValueError,
        match=r"table shape \(27, 3\) does not fit the trainer.*"
        r"need shape \(81, 3\).*no sidecar",
    ):
        run(TransferConfig(init=str(bare), arena=str(arena), iterations=10, seeds=(1,)))


def test_bare_table_of_the_right_shape_runs(tmp_path: Path, setup: tuple[Path, Path]) -> None:
    table, arena = setup
    bare = tmp_path / "bare.npy"
    np.save(bare, load_table(table).q)
    res = run(
        TransferConfig(init=str(bare), arena=str(arena), iterations=20, seeds=(1,), eval_steps=0)
    )
    assert res.table.sidecar is False and res.trainer_config.algo == "qlearning"
    assert math.isnan(res.runs[0].eval_collisions_per_1000)


def test_unknown_action_names_and_missing_files(tmp_path: Path, setup: tuple[Path, Path]) -> None:
    table, arena = setup
    meta = load_table(table).meta
    odd = TableMeta(**{**meta.__dict__, "actions": ["go", "left", "right"]})
    save_table(tmp_path / "odd", load_table(table).q, odd)
    with pytest.raises(ValueError, match="match no action set"):
        run(
            TransferConfig(
                init=str(tmp_path / "odd.npy"), arena=str(arena), iterations=10, seeds=(1,)
            )
        )
    with pytest.raises(ValueError, match="no such table"):
        run(TransferConfig(init=str(tmp_path / "nope.npy"), arena=str(arena), iterations=10))
    with pytest.raises(ValueError, match="unknown arena"):
        run(TransferConfig(init=str(table), arena="r9", iterations=10))


def test_same_arena_warning(setup: tuple[Path, Path], capsys: pytest.CaptureFixture[str]) -> None:
    table, _ = setup
    rc = main(
        [
            "transfer",
            "--init",
            str(table),
            "--arena",
            "r1",
            "--iterations",
            "20",
            "--seed",
            "1",
            "--eval-steps",
            "0",
            "--jobs",
            "1",
            "--json",
        ]
    )
    captured = capsys.readouterr()
    assert rc == 0 and json.loads(captured.out)["same_arena"] is True
    assert "warning" in captured.err


def test_aggregate_and_ratio_by_hand() -> None:
    # Prepare: per-seed values 1, 3 (init) and 4, 4 (zero)
    assert aggregate([1.0, 3.0]) == aggregate([3.0, 1.0])
    s = aggregate([1.0, 3.0])
    assert (s.mean, s.std, s.n) == (2.0, pytest.approx(math.sqrt(2.0)), 2)
    assert aggregate([5.0]).std == 0.0 and aggregate([float("nan")]).n == 0

    def fake(seed: int, cond: str, value: float) -> RunResult:
        z = np.zeros(1)
        vals = {m: value for m in METRICS}
        return RunResult(
            seed=seed,
            condition=cond,
            iterations=1,
            collisions=0,
            head_steps=1,
            head10_steps=1,
            respawns=0,
            wall_time=0.0,
            curve_iteration=z,
            curve_collisions=z,
            curve_reward=z,
            **vals,
        )

    summary, ratio = summarise(
        [fake(1, "init", 1.0), fake(1, "zero", 4.0), fake(2, "init", 3.0), fake(2, "zero", 4.0)]
    )
    assert summary["init"]["collisions_per_1000"].mean == 2.0
    assert summary["zero"]["collisions_per_1000"].std == 0.0
    assert ratio["collisions_per_1000"] == 0.5


def test_config_is_checked() -> None:
    with pytest.raises(ValueError, match="distinct"):
        TransferConfig(init="x.npy", arena="r1", seeds=(1, 1))
    with pytest.raises(ValueError, match="iterations"):
        TransferConfig(init="x.npy", arena="r1", iterations=0)
