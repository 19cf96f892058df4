"""The robot interface: both kinds of robot satisfy it, and the launcher's roster drives
robots through it alone (a scripted robot stands in for a process or a robot host)."""

from __future__ import annotations

import io
import json
import time
from pathlib import Path

import pytest

from dfrl.experiments.driver.config import RobotSpec
from dfrl.experiments.driver.launcher import robot_roster
from dfrl.experiments.driver.launcher.children import RobotChild
from dfrl.experiments.driver.launcher.events import EVENTS_FILE
from dfrl.experiments.driver.launcher.remote_robots import RemoteRobot, StatusPoller
from dfrl.experiments.driver.launcher.reporter import Reporter
from dfrl.experiments.driver.launcher.robot_roster import RobotRoster
from dfrl.experiments.driver.launcher.robots import Progress, Robot, RobotStatus, await_ready
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.robot_host.config import RobotConfig
from dfrl.experiments.robot_host.lines import Evaluation, Sample


class ScriptedRobot:
    """A robot whose status and reports the test sets (it implements :class:`Robot`)."""

    def __init__(self, rid: str, iterations: int = 100, robot_host: str | None = None) -> None:
        self._spec = RobotSpec(rid, "r1", robot_host=robot_host)
        self._cfg = RobotConfig(robot=rid, out_dir=".", iterations=iterations)
        self.now = RobotStatus(address=None, iteration=0, shares=0, done=False, running=False)
        self.pending = Progress()
        self.calls: list[str] = []
        self.gather_error: str | None = None

    @property
    def spec(self) -> RobotSpec:
        return self._spec

    @property
    def config(self) -> RobotConfig:
        return self._cfg

    def start(self) -> None:
        self.calls.append("start")
        self.now = RobotStatus(
            address=("127.0.0.1", 7001), iteration=0, shares=0, done=False, running=True, pid=4242
        )

    def status(self) -> RobotStatus:
        return self.now

    def take_progress(self) -> Progress:
        taken, self.pending = self.pending, Progress()
        return taken

    def request_stop(self) -> None:
        self.calls.append("request_stop")

    def stop(self, timeout_s: float) -> bool:
        self.calls.append(f"stop {timeout_s:.0f}")
        self.now = RobotStatus(
            self.now.address,
            self.now.iteration,
            self.now.shares,
            self.now.done,
            running=False,
            exit_code=0,
            pid=self.now.pid,
        )
        return True

    def gather(self, out: Path) -> list[str]:
        if self.gather_error:
            raise ExperimentError(self.gather_error)
        return ["logs/x.err"] if self._spec.robot_host else []

    def log_tail(self, lines: int = 8) -> str:
        return "Traceback: boom"


def events(out: Path) -> list[dict]:
    return [json.loads(x) for x in (out / EVENTS_FILE).read_text().splitlines()]


def test_both_kinds_of_robot_are_robots(tmp_path: Path) -> None:
    spec = RobotSpec("r1", "r1")
    child = RobotChild(spec, RobotConfig(robot="r1", out_dir=str(tmp_path)), tmp_path)
    remote = RemoteRobot(
        RobotSpec("r2", "r1", robot_host="127.0.0.1:7001"),
        RobotConfig(robot="r2", out_dir="."),
        console=None,  # type: ignore[arg-type]
        experiment="e",
        poller=StatusPoller(),
    )
    assert isinstance(child, Robot) and isinstance(remote, Robot)
    assert isinstance(ScriptedRobot("r3"), Robot)
    # made, not started: nothing runs, no address, no process
    assert child.status() == RobotStatus(None, 0, 0, False, False, None, None, None)
    assert remote.status().address is None and remote.status().pid is None


def test_roster_reports_a_crash_once_and_keeps_its_exit_code(tmp_path: Path) -> None:
    # Prepare
    said = io.StringIO()
    roster = RobotRoster(tmp_path, Reporter(tmp_path, said))
    r1, r2 = ScriptedRobot("r1"), ScriptedRobot("r2")
    for r in (r1, r2):
        r.start()
        roster.add(r)
    await_ready([r1, r2], timeout_s=1.0)
    # Execute: r2's process dies with exit code 3; the roster looks twice
    r2.now = RobotStatus(
        ("127.0.0.1", 7001),
        40,
        0,
        False,
        running=False,
        lost="process exited with code 3",
        exit_code=3,
        pid=4242,
    )
    roster.check()
    roster.check()
    # Assert
    assert roster.crashed() == {"r2": 3}
    assert roster.lost() == {"r2": "process exited with code 3"}
    assert said.getvalue().count("ROBOT r2 CRASHED (exit code 3) at iteration 40") == 1
    assert "Traceback: boom" in said.getvalue()
    assert [e["state"] for e in events(tmp_path)] == ["dead"]


def test_roster_says_a_lost_robot_host_and_its_return(tmp_path: Path) -> None:
    said = io.StringIO()
    roster = RobotRoster(tmp_path, Reporter(tmp_path, said))
    r = ScriptedRobot("r1", robot_host="10.0.0.7:7001")
    r.start()
    roster.add(r)
    r.now = RobotStatus(
        ("10.0.0.7", 7001), 50, 0, False, running=False, lost="unreachable for 11 s: timeout"
    )
    roster.check()
    r.now = RobotStatus(("10.0.0.7", 7001), 60, 0, False, running=True)
    roster.check()
    assert roster.crashed() == {} and roster.lost() == {}
    assert "ROBOT r1 LOST at iteration 50: unreachable for 11 s" in said.getvalue()
    assert "robot r1 answers again (iteration 60)" in said.getvalue()
    assert [e["state"] for e in events(tmp_path)] == ["dead", "learning"]


def _silent(rid: str, it: int, since: float, answered: float) -> RobotStatus:
    """A robot host's status while its polls fail (silent since ``since``)."""
    return RobotStatus(
        ("10.0.0.7", 7001),
        it,
        0,
        False,
        running=False,
        lost=f"unreachable for 11 s: {rid} timeout",
        silent_since=since,
        answered_at=answered,
    )


def test_roster_waits_out_its_own_partition(tmp_path: Path) -> None:
    # Prepare: three robots on robot hosts, all answering (times: time.monotonic's)
    t = time.monotonic()
    said = io.StringIO()
    roster = RobotRoster(tmp_path, Reporter(tmp_path, said), partition_wait_s=60.0)
    robots = [ScriptedRobot(f"r{i}", robot_host=f"10.0.0.{i}:7001") for i in (1, 2, 3)]
    for r in robots:
        r.start()
        roster.add(r)
        r.now = RobotStatus(("10.0.0.7", 7001), 10, 0, False, running=True, answered_at=t - 20)
    roster.check()
    # Execute: all three go silent together (none answered since), then come back
    for r in robots:
        r.now = _silent(r.spec.id, 20, t - 11, t - 12)
    roster.check()
    cut = roster.partitioned(), roster.all_exited(), roster.robots_done(), roster.lost()
    for r in robots:
        r.now = RobotStatus(("10.0.0.7", 7001), 30, 0, False, running=True, answered_at=t + 1)
    roster.check()
    # Assert: no robot called lost; the run is not over; a partition said, then healed
    assert cut == (True, False, False, {}), cut
    assert roster.lost() == {} and not roster.partitioned()
    text = said.getvalue()
    assert "DRIVER PARTITIONED: none of the 3 robot hosts answers" in text, text
    assert "driver partition healed" in text and "LOST" not in text, text
    assert [e["state"] for e in events(tmp_path)] == ["partitioned", "healed"]
    assert any("driver partitioned from all 3 robot hosts" in s for s in roster.stalls())


def test_roster_loses_a_silent_host_while_others_answer(tmp_path: Path) -> None:
    # Control: one robot host silent while the other answered since: that one is lost at once
    said = io.StringIO()
    roster = RobotRoster(tmp_path, Reporter(tmp_path, said), partition_wait_s=60.0)
    r1, r2 = (ScriptedRobot(f"r{i}", robot_host=f"10.0.0.{i}:7001") for i in (1, 2))
    for r in (r1, r2):
        r.start()
        roster.add(r)
    t = time.monotonic()
    r1.now = _silent("r1", 20, t - 11, t - 12)
    r2.now = RobotStatus(("10.0.0.2", 7001), 20, 0, False, running=True, answered_at=t - 0.5)
    roster.check()
    assert list(roster.lost()) == ["r1"] and not roster.partitioned()
    assert "ROBOT r1 LOST" in said.getvalue()


def test_roster_loses_them_after_the_partition_wait(tmp_path: Path) -> None:
    said = io.StringIO()
    roster = RobotRoster(tmp_path, Reporter(tmp_path, said), partition_wait_s=0.0)
    robots = [ScriptedRobot(f"r{i}", robot_host=f"10.0.0.{i}:7001") for i in (1, 2)]
    for r in robots:
        r.start()
        roster.add(r)
        r.now = _silent(r.spec.id, 20, 1.0, 0.5)  # silent for long (monotonic 1.0)
    roster.check()
    assert sorted(roster.lost()) == ["r1", "r2"] and not roster.partitioned()
    assert "count as lost from now on" in said.getvalue()


def test_roster_records_a_stall_when_the_robot_moves_again(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(robot_roster, "STALL_S", 0.0)
    roster = RobotRoster(tmp_path, Reporter(tmp_path, None))
    r = ScriptedRobot("r1")
    r.start()
    roster.add(r)
    roster.check()  # iteration 0 seen
    roster.check()  # no progress since: stalled
    assert roster.stalls() == []
    r.now = RobotStatus(r.now.address, 5, 0, False, running=True)
    roster.check()
    assert len(roster.stalls()) == 1 and "r1 made no progress at iteration 0" in roster.stalls()[0]


def test_roster_turns_progress_into_view_events(tmp_path: Path) -> None:
    roster = RobotRoster(tmp_path, Reporter(tmp_path, None))
    local, remote = ScriptedRobot("r1"), ScriptedRobot("r2", robot_host="10.0.0.7:7001")
    for r in (local, remote):
        r.start()
        roster.add(r)
    sample = Sample("r1", 10, 0.1, 0.2, 0.3, 4.0, 5.0)
    local.pending = Progress(sample=sample, evals=[Evaluation("r1", 10, 1.0, 0.5, 0.25)])
    remote.pending = Progress(
        sample=sample._replace(robot="r2"),
        error="KeyError: 'data'",
        outages=[(1.0, 2.0, "timeout")],
    )
    roster.show_progress()
    roster.show_progress()  # nothing new: no new events
    kinds = [(e["kind"], e.get("robot")) for e in events(tmp_path)]
    # a robot on another host: its samples also stand for its curves (progress events)
    assert kinds == [
        ("eval", "r1"),
        ("pose", "r1"),
        ("pose", "r2"),
        ("progress", "r2"),
        ("error", None),
    ]
    assert len(roster.stalls()) == 1 and "r2 unreachable" in roster.stalls()[0]


def test_roster_stops_every_robot_and_gathers_their_files(tmp_path: Path) -> None:
    said = io.StringIO()
    roster = RobotRoster(tmp_path, Reporter(tmp_path, said))
    local, remote = ScriptedRobot("r1"), ScriptedRobot("r2", robot_host="10.0.0.7:7001")
    bad = ScriptedRobot("r3", robot_host="10.0.0.8:7001")
    bad.gather_error = "r3: logs/r3.err came back with 0 of 10 bytes"
    for r in (local, remote, bad):
        r.start()
        roster.add(r)
    roster.shutdown()
    roster.gather(tmp_path)
    # every robot is asked first, then each is waited for
    assert local.calls == ["start", "request_stop", "stop 15"]
    assert roster.gathered() == {"r2": ["logs/x.err"]}
    assert roster.gather_errors() == [
        "files of r3 not gathered: r3: logs/r3.err came back with 0 of 10 bytes"
    ]
    roster.kill_all()  # nothing runs any more: no robot counts as killed
    assert all(c.startswith("stop") for c in (local.calls[-1], remote.calls[-1]))


def test_await_ready_says_which_robot_did_not_start(tmp_path: Path) -> None:
    r = ScriptedRobot("r1")
    r.now = RobotStatus(
        None, 0, 0, False, running=False, lost="process exited with code 1", exit_code=1, pid=4242
    )
    with pytest.raises(
        ExperimentError,
        match=r"robot r1 did not start \(exit code 1\): "
        "Traceback: boom",
    ):
        await_ready([r], timeout_s=5.0)
