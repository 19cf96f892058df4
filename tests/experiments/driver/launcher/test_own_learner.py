"""A learner defined outside the package (docs/learners/rbf_sarsa.py, copied into a folder of
the test's own), named in a config's ``learners``, in real federated runs: its two robots hold
the same parameters after every share, and it joins a grid federation with a Q-learning robot.
Also the config's errors, each located."""

from __future__ import annotations

import json
import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from dfrl.experiments.driver.config import ConfigError, ExperimentConfig
from dfrl.experiments.driver.launcher import run
from dfrl.experiments.processes import find_swipl
from dfrl.robots.grid_view import grid_table
from dfrl.robots import plugins
from dfrl.robots.plugins import load_class
from dfrl.robots.state import Discretiser
from dfrl.robots.td import LearnerParams

from .helpers import diagnose, rounds_csv
from .test_params_run import _assert_federated

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")

EXAMPLE = Path(__file__).resolve().parents[4] / "docs" / "learners" / "rbf_sarsa.py"


@pytest.fixture(autouse=True)
def _forget_plugins() -> Iterator[None]:
    """The learners these configs register stay registered in the process (a ``dfrl robot``
    service keeps them for its next run); here they are forgotten after each test, so that a
    later test in the same worker sees only the built-in learners."""
    before = dict(plugins._REGISTERED)
    yield
    plugins._REGISTERED.clear()
    plugins._REGISTERED.update(before)


def _config_file(folder: Path, robots: list[dict], **extra: object) -> Path:
    """The example learner copied beside a config that names it by a relative path."""
    shutil.copy(EXAMPLE, folder / "my_learner.py")
    data = {
        "name": "own",
        "robots": robots,
        "iterations": 300,
        "respite": 100,
        "seed": 1,
        "mode": "sync",
        "timeout_s": 120,
        "method": "average",
        "learners": {
            "rbf_sarsa": {"class": "my_learner.py:RbfSarsa", "options": {"alpha": 0.1, "lam": 0.8}}
        },
        **extra,
    }
    path = folder / "own.json"
    path.write_text(json.dumps(data))
    return path


def test_an_outside_learner_federates_with_equal_parameters_after_every_share(
    tmp_path: Path,
) -> None:
    # Prepare: two robots on the outside learner, sync, 3 rounds of FedAvg
    cfg = ExperimentConfig.load(
        _config_file(
            tmp_path,
            [
                {"id": "r1", "arena": "r1", "algo": "rbf_sarsa"},
                {"id": "r2", "arena": "r4", "algo": "rbf_sarsa"},
            ],
        )
    )
    # Execute
    res = run(cfg, tmp_path / "out", progress=None)
    # Assert: the agent carried its parameters and wrote the same FedAvg into both robots
    assert res.ok, (res.crashed, res.agents_finished, diagnose(tmp_path / "out"))
    digests = _assert_federated(tmp_path / "out", "fed_rbf_sarsa", 3, ("r1", "r2"))
    assert len(set(digests)) == 3, "the weights moved between rounds"
    weights = np.load(tmp_path / "out" / "params" / "r1.npy")
    assert weights.shape == (3 * (1 + 8 * 5),) and np.any(weights != 0)
    # the config in the results names the learner by an absolute path: it runs from there
    saved = json.loads((tmp_path / "out" / "config.json").read_text())
    spec = saved["learners"]["rbf_sarsa"]["class"]
    assert Path(spec.rpartition(":")[0]).is_absolute(), spec
    # the summary says what ran: the plug-in, its options, FedAvg
    summary = (tmp_path / "out" / "summary.md").read_text()
    assert "(rbf_sarsa): plug-in " in summary and "with alpha 0.1, lam 0.8" in summary
    assert "averaged by FedAvg" in summary


def test_an_outside_learner_joins_a_grid_federation_with_a_qlearning_robot(tmp_path: Path) -> None:
    cfg = ExperimentConfig.load(
        _config_file(
            tmp_path,
            [
                {"id": "r1", "arena": "r1", "algo": "qlearning"},
                {"id": "r2", "arena": "r4", "algo": "rbf_sarsa"},
            ],
            federation="grid",
        )
    )
    res = run(cfg, tmp_path / "out", progress=None)
    out = tmp_path / "out"
    assert res.ok and res.agents_finished == {"fed_grid": 3}, (res.crashed, diagnose(out))
    rows = rounds_csv(out)
    assert [(r["round"], r["visited"], r["error"]) for r in rows] == [
        (str(k), "r1 r2", "") for k in (1, 2, 3)
    ]
    # the outside learner's grid view, rebuilt from its parameters after each share, is near
    # the table the agent wrote into the Q-learning robot (it was distilled towards it)
    cls = load_class(f"{tmp_path / 'my_learner.py'}:RbfSarsa")
    learner = cls(8, 3, LearnerParams(), np.random.default_rng(0))
    for it in (100, 200, 300):
        aggregate = np.load(out / "tables" / "history" / f"r1_it{it}.npy")
        learner.set_params(np.load(out / "params" / "history" / f"r2_it{it}.npy"))
        view = grid_table(learner, Discretiser())
        before = np.sqrt(np.mean(aggregate**2))
        after = np.sqrt(np.mean((view - aggregate) ** 2))
        assert after < 0.5 * before, (it, after, before)


@pytest.mark.parametrize(
    "entry, said",
    [
        ("missing.py:RbfSarsa", "does not exist"),
        ("my_learner.py:Nothing", "has no Nothing"),
        ("json:JSONDecoder", "is not a subclass of dfrl.robots.approx.FunctionLearner"),
        ("no_such_module_here:X", "importing no_such_module_here failed"),
        ("my_learner.py", "expected 'module:Class'"),
    ],
)
def test_a_bad_learner_entry_is_a_located_config_error(
    tmp_path: Path, entry: str, said: str
) -> None:
    path = _config_file(tmp_path, [{"id": "r1", "arena": "r1", "algo": "qlearning"}])
    data = json.loads(path.read_text())
    data["learners"] = {"mine": entry}
    path.write_text(json.dumps(data))
    with pytest.raises(ConfigError) as err:
        ExperimentConfig.load(path)
    text = str(err.value)
    assert "learners.mine:" in text and said in text, text


def test_a_builtin_name_and_an_unknown_algo_are_refused(tmp_path: Path) -> None:
    path = _config_file(tmp_path, [{"id": "r1", "arena": "r1", "algo": "rbf_sarsaa"}])
    data = json.loads(path.read_text())
    data["learners"]["dqn"] = "my_learner.py:RbfSarsa"
    path.write_text(json.dumps(data))
    with pytest.raises(ConfigError) as err:
        ExperimentConfig.load(path)
    text = str(err.value)
    assert "learners.dqn: learner name 'dqn' is a built-in learner's" in text, text
    assert "robots[0].algo" in text and "rbf_sarsa" in text, text


def test_a_learner_without_q_model_is_refused_by_a_grid_federation(tmp_path: Path) -> None:
    source = tmp_path / "plain.py"
    source.write_text(EXAMPLE.read_text().replace("    def q_model(self)", "    def _no(self)"))
    path = _config_file(
        tmp_path,
        [
            {"id": "r1", "arena": "r1", "algo": "qlearning"},
            {"id": "r2", "arena": "r4", "algo": "plain"},
        ],
        federation="grid",
    )
    data = json.loads(path.read_text())
    data["learners"] = {"plain": "plain.py:RbfSarsa"}
    path.write_text(json.dumps(data))
    with pytest.raises(ConfigError) as err:
        ExperimentConfig.load(path)
    assert "robots[1].algo: plain has no q_model()" in str(err.value), str(err.value)


def test_a_config_names_only_its_own_plug_ins_not_those_an_earlier_config_registered(
    tmp_path: Path,
) -> None:
    # Prepare: a config with a learners section registers rbf_sarsa in this process
    ExperimentConfig.load(
        _config_file(tmp_path, [{"id": "r1", "arena": "r1", "algo": "rbf_sarsa"}])
    )
    assert "rbf_sarsa" in plugins.plugin_names()
    # Execute: another config names rbf_sarsa without a learners section of its own
    data = {"robots": [{"id": "r1", "arena": "r1", "algo": "rbf_sarsa"}]}
    with pytest.raises(ConfigError) as err:
        ExperimentConfig.from_dict(data)
    # Assert: refused, located (whether it checks depends on the config, not the process)
    assert "robots[0].algo: unknown algorithm 'rbf_sarsa'" in str(err.value), str(err.value)
    # control: with its own learners section the same robot is accepted
    ExperimentConfig.load(
        _config_file(tmp_path, [{"id": "r1", "arena": "r1", "algo": "rbf_sarsa"}])
    )
