"""A tree itinerary's copies are clones, and a remote ``dfrl robot`` admits its own number of
them a minute (``--clone-limit``, default 60): too few, and most rounds skip robots. The
driver now reads the host's limit from its status and refuses it before anything starts,
naming the option; the control is the same run on a host started with enough."""

from __future__ import annotations

from pathlib import Path

import pytest

from dfrl.experiments.driver.config import RobotSpec
from dfrl.experiments.driver.launcher import run
from dfrl.experiments.driver.launcher.spawn import clone_limit
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.processes import find_swipl

from .helpers import diagnose, robot_service, small_config

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="swipl not installed")


def _tree_config(port: int):
    cfg = small_config(2, iterations=200, respite=100, token=1111)
    return cfg.replace(
        itinerary="tree",
        fanout=2,
        robots=(cfg.robots[0], RobotSpec("r2", "r4", robot_host=f"127.0.0.1:{port}")),
    )


def test_a_host_short_of_clones_is_refused_before_the_run(tmp_path: Path) -> None:
    svc, port = robot_service(tmp_path / "svc")
    try:
        cfg = _tree_config(port)
        needs = clone_limit(cfg)
        with pytest.raises(
            ExperimentError,
            match=(
                rf"robot host 127.0.0.1:{port} admits 60 clones a minute, and "
                rf"this tree itinerary needs {needs} .*--clone-limit {needs}"
            ),
        ):
            run(cfg, tmp_path / "out", progress=None)
    finally:
        svc.terminate()
        svc.communicate(timeout=30)


def test_a_host_with_enough_clones_runs_the_tree(tmp_path: Path) -> None:
    cfg0 = _tree_config(1)
    svc, port = robot_service(tmp_path / "svc", "--clone-limit", str(clone_limit(cfg0)))
    try:
        res = run(_tree_config(port), tmp_path / "out", progress=None)
        assert res.ok, diagnose(tmp_path / "out")
    finally:
        svc.terminate()
        svc.communicate(timeout=30)
