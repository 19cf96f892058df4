"""The chaos benchmark against real node processes: no agent lost, doubled or left unsettled."""

from __future__ import annotations

import json

import pytest

from dfrl.experiments.tools.bench import chaos
from dfrl.experiments.cli import main
from dfrl.experiments.processes import find_swipl

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="swipl not installed")


def check(report: dict, faults: int) -> None:
    assert report["faults"] == faults
    assert (report["lost"], report["doubled"], report["unsettled"]) == (0, 0, 0), report
    assert report["moves"] > faults  # the agents kept moving
    assert sum(k["faults"] for k in report["by_kind"].values()) == faults
    assert all(k["hit"] == k["faults"] for k in report["by_kind"].values()), report


def test_the_sharpest_faults_quickly() -> None:
    kinds = ("kill_dest_after_staged", "kill_source_after_commit", "drop_commit")
    report = chaos.run(faults=3, seed=7, agents=3, kinds=kinds)
    check(report, 3)
    assert report["restarts"] == 2


@pytest.mark.slow
def test_every_kind_once_from_the_command_line(capsys: pytest.CaptureFixture[str]) -> None:
    n = len(chaos.FAULT_KINDS)
    assert main(["bench", "chaos", "--faults", str(n), "--seed", "3", "--json"]) == 0
    report = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    check(report, n)
    assert set(report["by_kind"]) == set(chaos.FAULT_KINDS)


def test_unknown_kind_is_refused() -> None:
    with pytest.raises(ValueError, match="unknown fault kinds"):
        chaos.run(faults=1, kinds=("meteor",))
