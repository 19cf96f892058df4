"""Experiment and robot process configurations: round trips, validation, shipped configs,
boundaries, the renamed robot_host key, one check per run."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from dfrl.experiments.driver import config as config_module
from dfrl.experiments.driver.config import ConfigError, ExperimentConfig, RobotSpec, parse_host_port
from dfrl.experiments.robot_host.config import RobotConfig, boundaries
from dfrl.experiments.robot_host import table_digest


def test_boundaries_and_digest() -> None:
    assert boundaries(1200, 500) == [500, 1000, 1200]
    assert boundaries(1000, 500) == [500, 1000]
    assert boundaries(300, 500) == [300]
    q = np.arange(6, dtype=np.float64).reshape(3, 2)
    assert table_digest(q) == table_digest(q.copy()) != table_digest(q + 1e-12)
    assert len(table_digest(q)) == 64


def test_configs_round_trip_and_validate() -> None:
    n = RobotConfig(robot="r1", out_dir="/tmp/x", mode="sync", rtf=1.0)
    assert RobotConfig.from_dict(n.to_dict()) == n
    with pytest.raises(ValueError):
        RobotConfig.from_dict({"robot": "r1", "out_dir": "x", "colour": 1})
    cfg = ExperimentConfig(
        robots=(RobotSpec("r1", "r1"), RobotSpec("r2", "r4", "sarsa")),
        iterations=1200,
        respite=500,
        methods={"sarsa": "max"},
    )
    assert cfg.rounds == 3
    assert cfg.algorithms() == ["qlearning", "sarsa"]
    assert cfg.method_for("sarsa") == "max" and cfg.method_for("qlearning") == "average"
    assert [cfg.robot_seed(r) for r in cfg.robots] == [1, 2]
    assert ExperimentConfig.from_dict(cfg.to_dict()) == cfg
    with pytest.raises(ValueError):
        ExperimentConfig(robots=(RobotSpec("r1", "r1"), RobotSpec("r1", "r2")))
    with pytest.raises(ValueError):
        RobotSpec("R1", "r1")


def test_shipped_configs_load() -> None:
    from dfrl.experiments.driver.config import CONFIGS_DIR

    names = sorted(p.stem for p in CONFIGS_DIR.glob("*.json"))
    assert {
        "demo",
        "paper_qlearning_average",
        "paper_qlearning_max",
        "paper_sarsa_average",
        "paper_sarsa_max",
        "hetero",
        "join",
    } <= set(names)
    for p in CONFIGS_DIR.glob("*.json"):
        ExperimentConfig.load(p)


def test_renamed_node_key_is_located_and_named() -> None:
    data = {
        "robots": [
            {"id": "r1", "arena": "r1"},
            {"id": "r2", "arena": "r4"},
            {"id": "r3", "arena": "r2", "node": "10.0.0.7:7001"},
        ],
        "joins": [{"robot": {"id": "r4", "arena": "r1", "node": "10.0.0.8:7001"}}],
    }
    with pytest.raises(ConfigError) as info:
        ExperimentConfig.from_dict(data)
    assert info.value.problems == [
        "robots[2].node: renamed robot_host (HOST:PORT of a dfrl robot service)",
        "joins[0].robot.node: renamed robot_host (HOST:PORT of a dfrl robot service)",
    ]
    data["robots"][2] = {"id": "r3", "arena": "r2", "robot_host": "10.0.0.7:7001"}
    data["joins"][0]["robot"] = {"id": "r4", "arena": "r1", "robot_host": "[::1]:7002"}
    cfg = ExperimentConfig.from_dict(data)
    assert cfg.robots[2].robot_host_address == ("10.0.0.7", 7001)
    assert cfg.joins[0].robot.robot_host_address == ("::1", 7002)
    assert [r.id for r in cfg.remote_robots()] == ["r3", "r4"]
    assert parse_host_port("h:1") == ("h", 1)
    with pytest.raises(ValueError, match="robot host 'h:0': use HOST:PORT"):
        parse_host_port("h:0")


def counting(monkeypatch: pytest.MonkeyPatch) -> list[bool]:
    """Count the checks of an experiment config's JSON form (one entry each: ``resources``)."""
    calls: list[bool] = []
    real = config_module.check_experiment

    def check(data: Any, resources: bool = True) -> list[str]:
        calls.append(resources)
        return real(data, resources=resources)

    monkeypatch.setattr(config_module, "check_experiment", check)
    return calls


def test_a_loaded_config_is_checked_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "cfg.json"
    path.write_text(
        json.dumps(
            {
                "comment": "two robots",
                "iterations": 300,
                "respite": 100,
                "robots": [
                    {"id": "r1", "arena": "r1"},
                    {"id": "r2", "arena": "r4", "algo": "sarsa"},
                ],
                "joins": [{"robot": {"id": "r3", "arena": "r2"}}],
            }
        )
    )
    calls = counting(monkeypatch)
    cfg = ExperimentConfig.load(path, {"seed": 4})
    cfg.check()  # the arenas were loaded by load()
    cfg = cfg.with_token("dfrl_" + "a" * 64)  # the token alone is checked
    cfg.check()
    assert calls == [True]
    assert cfg.seed == 4 and cfg.joins[0].robot.arena == "r2"
    with pytest.raises(ConfigError, match="token: not a token"):
        cfg.with_token("two words")
    cfg.replace(seed=5).check()  # a change: checked as a whole again
    assert calls == [True, False, True]


def test_dfrl_run_checks_the_config_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from dfrl.experiments import cli
    from dfrl.experiments.driver import launcher
    from dfrl.experiments.errors import ExperimentError

    seen: list[ExperimentConfig] = []

    def fake_run(cfg: ExperimentConfig, out: Path, **_: Any) -> None:
        cfg.check()  # what the launcher does first
        seen.append(cfg.with_token(cfg.token if cfg.token is not None else 7))
        raise ExperimentError("stopped before anything started")

    path = tmp_path / "cfg.json"
    path.write_text(json.dumps({"robots": [{"id": "r1", "arena": "r1"}], "iterations": 100}))
    monkeypatch.setattr(launcher, "run", fake_run)
    monkeypatch.chdir(tmp_path)
    calls = counting(monkeypatch)
    assert cli.main(["run", str(path), "--seed", "3"]) == 1
    assert calls == [True] and seen[0].seed == 3


def test_robot_host_needs_nothing_of_the_driver() -> None:
    code = (
        "import sys, dfrl.experiments.robot_host.config, dfrl.experiments.robot_host.service;"
        "print(sorted(m for m in sys.modules if '.driver' in m))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == "[]"


def test_function_learner_method_must_apply_to_params() -> None:
    """dqn + max and linear + visit_average are refused before anything starts, with the
    reason and the key; average (FedAvg) is accepted; a tabular robot may keep max."""
    from dfrl.experiments.driver.config_check import check_experiment

    robots = [{"id": "r1", "arena": "r1"}, {"id": "r2", "arena": "r4", "algo": "dqn"}]
    assert check_experiment({"robots": robots}, resources=False) == []
    problems = check_experiment({"robots": robots, "method": "max"}, resources=False)
    assert len(problems) == 1
    assert problems[0].startswith(
        "method: max does not apply to the dqn robots: dqn is a function learner"
    )
    assert "is no network" in problems[0] and '{"dqn": "average"}' in problems[0]
    assert (
        check_experiment(
            {"robots": robots, "method": "max", "methods": {"dqn": "average"}}, resources=False
        )
        == []
    )
    problems = check_experiment(
        {
            "robots": [{"id": "r1", "arena": "r1", "algo": "linear"}],
            "methods": {"linear": "visit_average"},
        },
        resources=False,
    )
    assert len(problems) == 1 and problems[0].startswith(
        "methods.linear: visit_average does not apply"
    )
    assert "no visit counts" in problems[0]
    joins = [{"robot": {"id": "r3", "arena": "r2", "algo": "dqn"}, "after_round": 1}]
    problems = check_experiment(
        {"robots": robots[:1], "joins": joins, "method": "max"}, resources=False
    )
    assert len(problems) == 1 and problems[0].startswith("method: max does not apply to the dqn")
    only_dqn = check_experiment({"robots": robots[1:], "method": "max"}, resources=False)
    assert len(only_dqn) == 1 and "tabular" not in only_dqn[0]  # no hint about others
    with pytest.raises(ConfigError, match="max does not apply"):
        ExperimentConfig(robots=(RobotSpec("r1", "r1", "dqn"),), method="max")


def test_resolved_config_writes_out_every_seed_and_trainer_setting() -> None:
    # Prepare: a config with one robot seed given, one left to the run, a joiner, and one
    # learner setting given (the rest of the learner's left to defaults)
    from dfrl.experiments.config_rules import check_trainer
    from dfrl.experiments.driver.config import JoinSpec
    from dfrl.robots.training import TrainerConfig

    cfg = ExperimentConfig(
        robots=(RobotSpec("r1", "r1"), RobotSpec("r2", "r4", seed=40)),
        joins=(JoinSpec(RobotSpec("r3", "r2")),),
        seed=7,
        trainer={"learner": {"alpha": 0.1}},
    )
    # Execute
    res = cfg.resolved()
    # Assert: the seeds the run uses, written out
    assert [r.seed for r in res.robots] == [7, 40] and res.joins[0].robot.seed == 9
    assert [res.robot_seed(r) for r in res.robots] == [cfg.robot_seed(r) for r in cfg.robots]
    # every trainer setting: the one given, the learner's others at their defaults
    d = TrainerConfig()
    learner = res.trainer["learner"]
    assert learner["alpha"] == 0.1 and learner["gamma"] == d.learner.gamma
    assert learner["epsilon"] == {
        "kind": d.learner.epsilon.kind.value,
        "start": d.learner.epsilon.start,
        "end": d.learner.epsilon.end,
        "decay_steps": d.learner.epsilon.decay_steps,
    }
    assert set(res.trainer) == set(d.to_dict(full=True)) - {"arena", "algo", "seed", "iterations"}
    assert check_trainer("trainer", res.trainer) == []
    # the robots train exactly as before: the same TrainerConfig from either trainer dict
    for a, b in ((cfg, cfg.trainer), (res, res.trainer)):
        node = RobotConfig(robot="r1", out_dir="/tmp/x", seed=a.robot_seed(a.robots[0]), trainer=b)
        assert (
            node.trainer_config()
            == RobotConfig(
                robot="r1", out_dir="/tmp/x", seed=7, trainer={"learner": {"alpha": 0.1}}
            ).trainer_config()
        )
    # it loads back through the same checks (as config.json, without the token), unchanged,
    # and resolves to itself
    back = ExperimentConfig.from_dict(json.loads(json.dumps(res.public_dict())))
    assert back == res and back.resolved() == res
    assert cfg.resolved() != cfg  # control: the unresolved config differs


@pytest.mark.parametrize("name", sorted(p.stem for p in config_module.CONFIGS_DIR.glob("*.json")))
def test_every_shipped_config_resolves_to_one_the_loader_takes(name: str, tmp_path: Path) -> None:
    # Prepare: a shipped config, resolved and written as a run writes it
    cfg = ExperimentConfig.load(config_module.resolve_config(name))
    path = tmp_path / "config.json"
    path.write_text(json.dumps(cfg.resolved().public_dict(), indent=2))
    # Execute: read back as dfrl run reads a config file (arenas included)
    back = ExperimentConfig.load(path)
    # Assert: nothing refused, the same experiment, every robot seeded
    assert back == cfg.resolved() and back.resolved() == back
    assert all(r.seed is not None for r in back.robots)
    assert [back.robot_seed(r) for r in back.robots] == [cfg.robot_seed(r) for r in cfg.robots]
