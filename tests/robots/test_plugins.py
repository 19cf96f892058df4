"""The learner interface (robots/README.md, "Bring your own learner"): the four built-in learners
implement it, and a learner from outside the package is found by an installed entry point or by
a spec, and trained by the Trainer like a built-in."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dfrl.robots.learners import LEARNERS, learner_class, make_learner
from dfrl.robots.plugins import PluginError, register_learner
from dfrl.robots.td import LearnerParams
from dfrl.robots.training import TrainerConfig, train

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "learners" / "rbf_sarsa.py"


@pytest.mark.parametrize("name", sorted(LEARNERS))
def test_every_builtin_learner_offers_the_interface(name: str) -> None:
    n_inputs = 243 if LEARNERS[name].kind == "tabular" else 8
    learner = make_learner(name, n_inputs, 3, LearnerParams(), np.random.default_rng(1))
    x = 7 if learner.kind == "tabular" else np.full(8, 0.3)
    a = learner.act(x)
    assert a in (0, 1, 2)
    assert learner.learn(x, a, 1.0, x, False) in (0, 1, 2)
    vec = learner.get_params()
    assert vec.ndim == 1 and vec.size == sum(int(np.prod(s)) for _, s in learner.param_layout)
    learner.set_params(vec + 1.0)
    assert np.array_equal(learner.get_params(), vec + 1.0)
    with pytest.raises(ValueError):
        learner.set_params(np.full(vec.size, np.nan))
    info = learner.describe()
    assert info["name"] == name and info["gamma"] == 0.95
    assert info["epsilon"] == {"kind": "linear", "start": 0.3, "end": 0.02, "decay_steps": 4000}


def test_a_registered_file_learner_trains_like_a_builtin() -> None:
    register_learner("rbf_example", f"{EXAMPLE}:RbfSarsa", {"alpha": 0.2})
    result = train(TrainerConfig(algo="rbf_example", arena="r1", iterations=600, seed=3))
    again = train(TrainerConfig(algo="rbf_example", arena="r1", iterations=600, seed=3))
    assert result.q_table is None and result.params is not None
    assert np.array_equal(result.params, again.params), "same seed, same parameters"
    assert np.any(result.params != 0)
    learner = learner_class("rbf_example")(
        8, 3, LearnerParams(), np.random.default_rng(0), alpha=0.2
    )
    assert learner.describe()["alpha"] == 0.2 and learner.describe()["grid"] is True


def test_a_builtin_name_cannot_be_taken() -> None:
    with pytest.raises(PluginError, match="built-in"):
        register_learner("dqn", f"{EXAMPLE}:RbfSarsa")


def test_an_installed_entry_point_is_found_by_name(tmp_path: Path) -> None:
    # a distribution on the path: its metadata declares the entry point, its module the class
    site = tmp_path / "site"
    info = site / "myplug-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: myplug\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[dfrl.learners]\nmyplug = myplug_mod:RbfSarsa\n")
    (site / "myplug_mod.py").write_text(EXAMPLE.read_text())
    code = (
        "from dfrl.robots.learners import learner_class, learner_kind;"
        "from dfrl.robots.plugins import plugin_names;"
        "print(learner_class('myplug').__name__, learner_kind('myplug'), plugin_names())"
    )
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), *sys.path])}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=120
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.split()[:2] == ["RbfSarsa", "function"], out.stdout
    assert "'myplug'" in out.stdout
    # control: without the distribution on the path the name is unknown, and said so
    bare = subprocess.run(
        [
            sys.executable,
            "-c",
            "from dfrl.robots.learners import learner_class; learner_class('myplug')",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert bare.returncode != 0 and "unknown learner 'myplug'" in bare.stderr
