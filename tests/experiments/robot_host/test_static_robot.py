"""A static robot (robot_host/static_robot.py): what a config's ``bench_table`` or
``bench_params`` asks for, and ``Training`` taking the robot it serves from that one seam."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np

from dfrl.experiments.robot_host.config import RobotConfig
from dfrl.experiments.robot_host.lines import ProtocolLines
from dfrl.experiments.robot_host.static_robot import StaticRobot, network_layout, static_robot
from dfrl.experiments.robot_host.training import Training
from dfrl.pybridge.providers import StaticParams, StaticTable
from dfrl.robots.training import TrainerConfig


class RecordingBridge:
    """The two calls ``Training`` makes of a bridge for a static robot, recorded."""

    def __init__(self) -> None:
        self.registered: dict[str, tuple[Any, Any, str]] = {}

    def register_robot(self, robot: str, table: Any, *, shape: Any, algo: str) -> None:
        self.registered[robot] = (table, shape, algo)

    def unregister_robot(self, robot: str) -> None:
        del self.registered[robot]


def test_a_learning_robot_asks_for_no_static_robot(tmp_path: Path) -> None:
    assert static_robot(RobotConfig(robot="r1", out_dir=str(tmp_path))) is None


def test_bench_table_asks_for_a_seeded_random_table(tmp_path: Path) -> None:
    robot = static_robot(RobotConfig(robot="r1", out_dir=str(tmp_path), seed=3, bench_table=[5, 4]))
    assert robot is not None and robot.shape == (5, 4)
    assert np.array_equal(robot.base.q_table, StaticTable((5, 4), 3).q_table)


def test_bench_params_asks_for_the_network_of_its_learner(tmp_path: Path) -> None:
    robot = static_robot(
        RobotConfig(
            robot="r1", out_dir=str(tmp_path), algo="linear", seed=2, bench_params={"samples": 7}
        )
    )
    assert robot is not None and robot.shape is None
    layout = network_layout(TrainerConfig(algo="linear"))
    assert robot.base.param_layout == layout and robot.base.samples == 7
    assert np.array_equal(robot.base.params, StaticParams(layout, 2, 7).params)


def test_training_serves_what_its_static_source_gives(tmp_path: Path) -> None:
    # Prepare: a static robot of parameters, given through the seam (no bench_ key at all)
    base = StaticParams([("w", (2, 3))], seed=1, samples=4)
    config = RobotConfig(robot="r1", out_dir=str(tmp_path), algo="dqn")
    bridge = RecordingBridge()
    run = Training(
        config,
        bridge,
        ProtocolLines(io.StringIO(), "r1"),
        static_source=lambda c: StaticRobot(base, None),
    )
    # Execute
    assert run.open() is None
    assert bridge.registered == {}  # opening offers nothing yet
    run.register()
    table, shape, algo = bridge.registered["r1"]
    table.set_params(np.ones(6))  # an agent's write
    run.close()
    # Assert: served as given, not simulated, and what the agents left it saved at close
    assert shape is None and algo == "dqn" and not run.simulated
    assert bridge.registered == {}
    assert np.array_equal(np.load(tmp_path / "params" / "r1.npy"), np.ones(6))
    assert (tmp_path / "shares_r1.csv").is_file()
