"""The config of one robot process: every problem at once, checked once, a JSON round trip."""

from __future__ import annotations

from typing import Any

import pytest

from dfrl.experiments.config_rules import ConfigError
from dfrl.experiments.robot_host import config as config_module
from dfrl.experiments.robot_host.config import Mode, RobotConfig, boundaries


def test_every_problem_with_its_key() -> None:
    with pytest.raises(ConfigError) as info:
        RobotConfig.from_dict(
            {
                "robot": "R1",
                "out_dir": 3,
                "mode": "fast",
                "colur": 1,
                "rtf": float("inf"),
                "bench_table": [4, 0],
            }
        )
    assert info.value.problems == [
        "colur: unknown key (known: algo, arena, bench_params, bench_table, clone_limit, "
        "eval_every, eval_steps, events, grace_s, host, iterations, learners, mode, out_dir, "
        "progress_every, respite, robot, rtf, seed, sync_timeout_s, tls, token, trainer)",
        "out_dir: expected a string, got 3 (an integer)",
        "mode: unknown mode 'fast'; known: async, sync",
        "rtf: must be a finite number, got inf",
        "robot: robot id 'R1': use a lower-case name like r1 (letters, digits, _)",
        "bench_table: expected [STATES, ACTIONS], two positive integers, got [4, 0]",
    ]
    with pytest.raises(ConfigError, match="iterations: must be >= 0, got -1"):
        RobotConfig(robot="r1", out_dir="x", iterations=-1)


def test_checked_once_and_round_trip(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[dict[str, Any]] = []
    real = config_module.check_robot_config
    monkeypatch.setattr(
        config_module, "check_robot_config", lambda data: calls.append(data) or real(data)
    )
    data = {
        "robot": "r1",
        "out_dir": "/tmp/x",
        "mode": "sync",
        "token": "dfrl_tok",
        "trainer": {"learner": {"alpha": 0.3}},
    }
    cfg = RobotConfig.from_dict(data)
    assert len(calls) == 1 and cfg.mode is Mode.SYNC
    assert RobotConfig.from_dict(cfg.to_dict()) == cfg
    assert "token" not in cfg.public_dict() and cfg.to_dict()["token"] == "dfrl_tok"
    assert cfg.trainer_config().learner.alpha == 0.3
    assert boundaries(0, 500) == []


def test_the_checked_mark_is_no_key(monkeypatch: pytest.MonkeyPatch) -> None:
    # what from_dict passes to say "checked as a whole" is neither read from nor written to JSON
    with pytest.raises(ConfigError, match="_checked: unknown key"):
        RobotConfig.from_dict({"robot": "r1", "out_dir": "x", "iterations": -1, "_checked": True})
    cfg = RobotConfig.from_dict({"robot": "r1", "out_dir": "x"})
    assert "_checked" not in cfg.to_dict()
    calls: list[dict[str, Any]] = []
    real = config_module.check_robot_config
    monkeypatch.setattr(
        config_module, "check_robot_config", lambda data: calls.append(data) or real(data)
    )
    RobotConfig(robot="r1", out_dir="x")  # built in Python: checked, once
    assert len(calls) == 1
