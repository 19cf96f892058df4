"""``dfrl run`` / ``demo`` / ``join`` refuse bad input before anything starts: every problem with
its key path, exit status 2, no results folder; results folders are never shared."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import pytest

from dfrl.experiments.cli import main
from dfrl.experiments.driver.config import ConfigError, ExperimentConfig
from dfrl.experiments.robot_host.config import RobotConfig, check_robot_config
from dfrl.experiments.driver.results.files import claim_output, new_run_folder


def smoke(**changes: Any) -> dict[str, Any]:
    cfg = {
        "name": "bad",
        "robots": [{"id": "r1", "arena": "r1"}, {"id": "r2", "arena": "r4"}],
        "iterations": 200,
        "respite": 50,
        "mode": "sync",
    }
    cfg.update(changes)
    return cfg


def run_cli(
    tmp_path: Path, cfg: dict[str, Any], capsys: pytest.CaptureFixture[str], *extra: str
) -> tuple[int, str]:
    path = tmp_path / "cfg.json"
    path.write_text(json.dumps(cfg))
    code = main(["run", str(path), *extra])
    err = capsys.readouterr().err
    return code, err


@pytest.fixture(autouse=True)
def in_tmp(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)


def assert_refused(tmp_path: Path, code: int, err: str, *located: str) -> None:
    assert code == 2, err
    assert "nothing was started" in err
    for text in located:
        assert text in err, err
    assert not (tmp_path / "results").exists()  # no folder, no process


def test_robot_key_typo(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = smoke()
    cfg["robots"][0]["algorithm"] = "sarsa"
    assert_refused(
        tmp_path,
        *run_cli(tmp_path, cfg, capsys),
        "robots[0].algorithm: unknown key; did you mean 'algo'?",
    )


def test_iterations_as_text(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert_refused(
        tmp_path,
        *run_cli(tmp_path, smoke(iterations="2000"), capsys),
        "iterations: expected an integer, got '2000' (a string)",
    )


def test_missing_arena(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = smoke()
    cfg["robots"][1]["arena"] = "r9"
    assert_refused(tmp_path, *run_cli(tmp_path, cfg, capsys), "robots[1].arena: unknown arena 'r9'")


def test_arena_file_that_does_not_parse(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "broken.json"
    bad.write_text('{"size": [2.0, 2.0], "blocks": [')
    cfg = smoke()
    cfg["robots"][0]["arena"] = str(bad)
    code, err = run_cli(tmp_path, cfg, capsys)
    assert_refused(tmp_path, code, err, "robots[0].arena: ", "broken.json")


def test_unknown_algorithm(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = smoke()
    cfg["robots"][1]["algo"] = "ppo"
    assert_refused(
        tmp_path,
        *run_cli(tmp_path, cfg, capsys),
        "robots[1].algo: unknown algorithm 'ppo'; known: dqn, linear, qlearning, sarsa",
    )


def test_unknown_method_config_and_flag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert_refused(
        tmp_path,
        *run_cli(tmp_path, smoke(method="median"), capsys),
        "method: unknown method 'median'; known: average, max, visit_average",
    )
    assert_refused(
        tmp_path,
        *run_cli(tmp_path, smoke(), capsys, "--method", "trimmed"),
        "method: unknown method 'trimmed'",
    )
    assert_refused(
        tmp_path,
        *run_cli(tmp_path, smoke(methods={"sarsa": "nope"}), capsys),
        "methods.sarsa: unknown method 'nope'",
    )


def test_ranges_unique_ids_and_nodes(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = smoke(respite=0, rtf=0, timeout_s=-1, tolerate_lost_robots=-1)
    cfg["robots"][1]["id"] = "r1"
    cfg["robots"].append({"id": "R3", "arena": "r2", "robot_host": "nohost"})
    assert_refused(
        tmp_path,
        *run_cli(tmp_path, cfg, capsys),
        "respite: must be >= 1, got 0",
        "rtf: must be > 0, got 0 (null means flat out)",
        "timeout_s: must be > 0",
        "tolerate_lost_robots: must be >= 0",
        "robots[1].id: robot id 'r1' is already used by robots[0]",
        "robots[2].id: robot id 'R3'",
        "robots[2].robot_host: robot host 'nohost'",
    )


def test_every_problem_at_once(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = smoke(iterations="2000", method="median", colour="red")
    cfg["robots"][0]["algorithm"] = "x"
    cfg["robots"][1].update(algo="ppo", arena="r9")
    code, err = run_cli(tmp_path, cfg, capsys)
    assert_refused(
        tmp_path,
        code,
        err,
        "the config has 6 problems",
        "colour: unknown key",
        "iterations:",
        "method:",
        "robots[0].algorithm:",
        "robots[1].algo:",
        "robots[1].arena:",
    )
    with pytest.raises(ConfigError) as info:
        ExperimentConfig.from_dict(cfg, resources=True)
    assert len(info.value.problems) == 6


def test_trainer_fields_checked(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cfg = smoke(trainer={"learner": {"alpha": "fast", "gamma_x": 1}, "seed": 3})
    assert_refused(
        tmp_path,
        *run_cli(tmp_path, cfg, capsys),
        "trainer.learner.alpha: expected a number",
        "trainer.learner.gamma_x: unknown key",
        "trainer.seed: set by the experiment",
    )


def test_bad_flags_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "cfg.json"
    path.write_text(json.dumps(smoke()))
    for argv in (
        ["run", str(path), "--rtf", "0"],
        ["run", str(path), "--iterations", "2k"],
        ["run", "no_such_config"],
    ):
        with pytest.raises(SystemExit) if argv[-1] != "no_such_config" else _nothing() as _:
            assert main(argv) == 2
    assert not (tmp_path / "results").exists()


class _nothing:
    def __enter__(self) -> None:
        return None

    def __exit__(self, *exc: object) -> bool:
        return False


def test_join_bad_robot_id_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "nodes.json").write_text(
        json.dumps({"token": 1, "nodes": [], "agents": [], "console": ["127.0.0.1", 1]})
    )
    assert main(["join", str(tmp_path / "run"), "--robot", "R6", "--arena", "r1"]) == 2
    assert "robot id 'R6'" in capsys.readouterr().err


def test_node_config_checked() -> None:
    problems = check_robot_config(
        {
            "robot": "r1",
            "out_dir": "x",
            "iterations": -1,
            "rtf": -2,
            "bench_table": [5],
            "events": "yes",
            "mode": "fast",
        }
    )
    text = "\n".join(problems)
    for located in (
        "iterations: must be >= 0",
        "rtf: must be >= 0",
        "bench_table: expected",
        "events: expected true or false",
        "mode: unknown mode 'fast'",
    ):
        assert located in text, text
    with pytest.raises(ConfigError, match="colour: unknown key"):
        RobotConfig.from_dict({"robot": "r1", "out_dir": "x", "colour": 1})


def test_out_refused_unless_force(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "old"
    (out / "tables").mkdir(parents=True)
    (out / "config.json").write_text("{}")
    (out / "tables" / "r3.npy").write_text("x")
    code, err = run_cli(tmp_path, smoke(), capsys, "--out", str(out))
    assert code == 2 and "is not empty" in err and "--force" in err
    assert (out / "tables" / "r3.npy").is_file()  # untouched
    claim_output(out, force=True)
    assert list(out.iterdir()) == []  # emptied: nothing left to mix in
    other = tmp_path / "mine"
    other.mkdir()
    (other / "notes.txt").write_text("keep me")
    with pytest.raises(FileExistsError, match="does not look like a results folder"):
        claim_output(other, force=True)
    assert (other / "notes.txt").is_file()


def test_default_out_is_a_new_timestamped_folder(tmp_path: Path) -> None:
    a = new_run_folder(tmp_path / "results", "demo", stamp="2026-12-01T17-03-12")
    b = new_run_folder(tmp_path / "results", "demo", stamp="2026-12-01T17-03-12")
    assert a.name == "2026-12-01T17-03-12" and b.name == "2026-12-01T17-03-12-2"
    latest = tmp_path / "results" / "demo" / "latest"
    assert latest.is_symlink() and os.readlink(latest) == b.name
    assert latest.resolve() == b.resolve()


@pytest.mark.parametrize(
    "arena, located",
    [
        (
            {
                "name": "mine",
                "size": [1.0, 0.8],
                "wall_height": 0.1,
                "blocks": [{"center": [0.2, 0.1], "size": [0.1, 0.2, 0.1]}],
                "start": {"pose": [0.2, -0.02, 0.0]},
            },
            "only 0.020 m from a block or wall",
        ),
        (
            {
                "name": "mine",
                "size": [1.0, 0.8],
                "wall_height": 0.1,
                "blocks": [
                    {"center": [0.2, 0.1], "size": [0.1, 0.2, 0.1]},
                    {"center": [0.25, 0.1], "size": [0.1, 0.2, 0.1]},
                ],
                "start": {"pose": [-0.3, -0.2, 0.0]},
            },
            "blocks[1]: overlaps blocks[0]",
        ),
    ],
)
def test_arena_with_a_start_pose_too_close_or_overlapping_blocks(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], arena: dict[str, Any], located: str
) -> None:
    path = tmp_path / "mine.json"
    path.write_text(json.dumps(arena))
    cfg = smoke()
    cfg["robots"][0]["arena"] = str(path)
    code, err = run_cli(tmp_path, cfg, capsys)
    assert_refused(tmp_path, code, err, "robots[0].arena: ", located)
