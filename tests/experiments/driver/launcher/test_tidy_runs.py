"""Real runs (robot processes, agents): the tidy tables load into pandas in one line and pivot
on their keys for a chain, a tree, a grid and a parameters federation; a run's config.json
(the resolved config) runs the same experiment again, metrics byte for byte."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pandas as pd
import pytest

from dfrl.experiments.driver.config import ExperimentConfig, RobotSpec
from dfrl.experiments.driver.launcher import run
from dfrl.experiments.driver.results.tidy import TIDY_KEYS
from dfrl.experiments.processes import find_swipl
from dfrl.experiments.provenance import PACKAGES

from .helpers import diagnose, rounds_csv, small_config

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")

#: 2 rounds of 30 iterations: enough for every kind of row, a few seconds a run
SMALL = {"iterations": 60, "respite": 30}


def _run(cfg: ExperimentConfig, out: Path) -> None:
    res = run(cfg, out, progress=None)
    assert res.ok, diagnose(out)


def _assert_tidy(out: Path, cfg: ExperimentConfig, agent: str) -> None:
    """Every tidy table: loads in one line, keys unique, pivots on them to the wide files'
    values; each row names its robot's algorithm, arena and agent as the config does."""
    tables = {name: pd.read_csv(out / "tidy" / f"{name}.csv") for name in TIDY_KEYS}
    for name, key in TIDY_KEYS.items():
        assert len(tables[name]) > 0, name
        assert not tables[name].duplicated(list(key)).any(), name
    robots = [r.id for r in cfg.robots]
    where = {r.id: (r.algo, r.arena) for r in cfg.robots}
    steps = tables["steps"]
    assert len(steps) == len(robots) * cfg.iterations
    for name in ("steps", "shares", "rounds"):
        t = tables[name]
        assert {(r.robot, r.algo, r.arena) for r in t.itertuples()} == {
            (rid, *where[rid]) for rid in robots
        }, name
    assert set(steps["agent"]) == {agent} and set(tables["shares"]["agent"]) == {agent}
    # steps: the q_sum curves of metrics.csv, a column per robot
    wide = steps.pivot(index="iteration", columns="robot", values="q_sum")
    metrics = pd.read_csv(out / "metrics.csv").pivot(
        index="iteration", columns="robot", values="q_sum"
    )
    assert wide.equals(metrics)
    shared = steps[steps["phase"] == "share"]
    assert sorted(set(shared["iteration"])) == [cfg.respite, 2 * cfg.respite]
    assert shared.groupby("robot")["round"].apply(list).to_dict() == {rid: [1, 2] for rid in robots}
    # shares: a write per robot per round, the digest the wide rounds.csv has
    by_round = tables["shares"].pivot(index="round", columns="robot", values="digest")
    rounds = tables["rounds"].pivot(index=["agent", "round"], columns="robot", values="digest")
    for row in rounds_csv(out):
        for rid in robots:
            assert rounds.loc[(agent, int(row["round"])), rid] == row[f"digest_{rid}"]
            assert by_round.loc[int(row["round"]), rid] == row[f"digest_{rid}"]
    assert set(tables["rounds"]["outcome"]) == {"written"}


def test_chain_tidy_and_rerun_from_its_config(tmp_path: Path) -> None:
    # Prepare: a chain run whose config leaves seeds and trainer settings to defaults
    cfg = small_config(2, **SMALL)
    assert all(r.seed is None for r in cfg.robots) and cfg.trainer == {}
    first, again = tmp_path / "a", tmp_path / "b"
    _run(cfg, first)
    _assert_tidy(first, cfg, "fed_qlearning")
    written = json.loads((first / "config.json").read_text())
    assert [r["seed"] for r in written["robots"]] == [1, 2]
    assert written["trainer"]["learner"]["alpha"] > 0 and written["trainer"]["learner"]["gamma"]
    assert set(written["trainer"]["learner"]["epsilon"]) == {"kind", "start", "end", "decay_steps"}
    made_by = json.loads((first / "provenance.json").read_text())
    assert set(PACKAGES) <= set(made_by) and made_by["swipl"] and made_by["command"]
    assert made_by["git"]["commit"] or made_by["git"]["note"]
    # Execute: dfrl run RESULTS/config.json, nothing else from the first run
    from dfrl.experiments import cli

    assert cli.main(["run", str(first / "config.json"), "--out", str(again)]) == 0
    # Assert: the same config, the same curves and steps, byte for byte
    for name in (
        "config.json",
        "metrics.csv",
        "metrics_r1.csv",
        "metrics_r2.csv",
        "tidy/steps.csv",
        "tables/r1.npy",
        "tables/r2.npy",
    ):
        assert (first / name).read_bytes() == (again / name).read_bytes(), (
            name,
            diagnose(first, again),
        )
    # control: the shares' wall times differ, so the byte comparison can fail
    assert (first / "tidy/shares.csv").read_bytes() != (again / "tidy/shares.csv").read_bytes()


def test_tree_tidy(tmp_path: Path) -> None:
    cfg = small_config(3, itinerary="tree", **SMALL)
    _run(cfg, tmp_path)
    _assert_tidy(tmp_path, cfg, "fed_qlearning")


def test_grid_tidy(tmp_path: Path) -> None:
    robots = (RobotSpec("r1", "r1", "qlearning"), RobotSpec("r2", "r4", "linear"))
    cfg = small_config(robots=robots, federation="grid", **SMALL)
    _run(cfg, tmp_path)
    _assert_tidy(tmp_path, cfg, "fed_grid")


def test_params_tidy(tmp_path: Path) -> None:
    robots = (RobotSpec("r1", "r1", "linear"), RobotSpec("r2", "r4", "linear"))
    cfg = small_config(robots=robots, **SMALL)
    _run(cfg, tmp_path)
    _assert_tidy(tmp_path, cfg, "fed_linear")
    with open(tmp_path / "tidy" / "steps.csv", newline="", encoding="utf-8") as fh:
        assert all(r["algo"] == "linear" for r in csv.DictReader(fh))
