"""``dfrl hetero --sim batched``: the Q-learning robots batched, the dqn on pybullet, both
recorded; a run is the same with the same seed, the dqn alone is the pybullet run, the
Q-learning robot alone is the batched trainer's robot, and federating still changes both."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from dfrl.experiments.cli import main
from dfrl.experiments.science.studies.hetero import HeteroOptions, run, run_one, trainer_config
from dfrl.experiments.science.studies.hetero_batched import run_one_batched
from dfrl.robots.batched.training import BatchedTrainer

TINY = HeteroOptions(
    seeds=(1, 2),
    iterations=60,
    respite=30,
    eval_at=(30, 60),
    eval_steps=20,
    episode_steps=20,
    jobs=1,
    sim="batched",
)


def test_batched_study_on_a_tiny_budget(tmp_path: Path) -> None:
    res = run(TINY, tmp_path / "out")
    assert len(res.rows) == 2 * 6 * 2
    assert {(r["algo"], r["sim"]) for r in res.rows} == {
        ("qlearning", "batched"),
        ("dqn", "pybullet"),
    }
    head = (tmp_path / "out" / "rows.csv").read_text().splitlines()[0]
    assert head.startswith("seed,run,role,algo,sim,iteration,score")
    assert res.sim == "batched" and res.simulators == {"qlearning": "batched", "dqn": "pybullet"}
    saved = json.loads((tmp_path / "out" / "results.json").read_text())
    assert saved["sim"] == "batched" and saved["simulators"]["dqn"] == "pybullet"
    assert json.loads((tmp_path / "out" / "options.json").read_text())["sim"] == "batched"
    assert res.residuals["shares"] == 2 * 2
    again = run_one_batched("mixed", 1, TINY)
    order = lambda r: (r["role"], r["iteration"])  # noqa: E731
    assert sorted(again["rows"], key=order) == [
        r for r in res.rows if r["seed"] == 1 and r["run"] == "mixed"
    ]
    assert again["digests"] == res.digests["mixed/1"]
    assert res.digests["mixed/1"]["dqn"] != res.digests["dqn_alone/1"]["dqn"]
    assert res.digests["mixed/1"]["ql"] != res.digests["ql_alone/1"]["ql"]
    assert res.digests["ql_pair/1"]["ql"] != res.digests["ql_alone/1"]["ql"]


def test_each_robot_is_its_simulators_robot() -> None:
    # the dqn alone runs on pybullet whatever --sim: the pybullet run, bit for bit
    pyb = HeteroOptions(**{**TINY.__dict__, "sim": "pybullet"})
    batched, plain = run_one_batched("dqn_alone", 1, TINY), run_one("dqn_alone", 1, pyb)
    assert batched["rows"] == plain["rows"] and batched["digests"] == plain["digests"]
    assert {r["sim"] for r in plain["rows"]} == {"pybullet"}
    # the Q-learning robot alone is the batched trainer's robot of its seed
    bt = BatchedTrainer([trainer_config("qlearning", 1001, TINY)])
    bt.run(60)
    alone = run_one_batched("ql_alone", 1, TINY)
    assert alone["digests"]["ql"] == hashlib.sha256(bt.q[0].tobytes()).hexdigest()
    assert alone["digests"] != run_one("ql_alone", 1, pyb)["digests"]  # another simulator


def test_cli_says_which_simulator_ran(capsys: pytest.CaptureFixture[str]) -> None:
    assert (
        main(
            [
                "hetero",
                "--seeds",
                "1",
                "2",
                "--iterations",
                "40",
                "--respite",
                "20",
                "--eval-at",
                "40",
                "--eval-steps",
                "20",
                "--jobs",
                "1",
            ]
        )
        == 0
    )
    assert "simulator: qlearning batched, dqn pybullet" in capsys.readouterr().out
    with pytest.raises(SystemExit):  # not a simulator: refused by argparse
        main(["hetero", "--seeds", "1", "2", "--sim", "mujoco"])
