"""The robot node process on its own (no agent): protocol lines, files, stopping."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from dfrl.experiments.robot_host.config import RobotConfig
from dfrl.experiments.robot_host.lines import parse_sample

REPO = Path(__file__).resolve().parents[3]


def _start(tmp_path: Path, **kw) -> subprocess.Popen:
    cfg = RobotConfig(robot="r7", out_dir=str(tmp_path), arena="r2", **kw)
    path = tmp_path / "node.json"
    path.write_text(json.dumps(cfg.to_dict()))
    return subprocess.Popen(
        [sys.executable, "-m", "dfrl.experiments.robot_host", "--config", str(path)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=REPO,
    )


def _line(p: subprocess.Popen, samples: list | None = None) -> list[str]:
    """The next protocol line that is not a DFRL_SAMPLE (those go to ``samples``)."""
    for _ in range(100):
        line = p.stdout.readline()
        sample = parse_sample(line)
        if sample is None:
            return line.split()
        if samples is not None:
            samples.append(sample)
    raise AssertionError("only DFRL_SAMPLE lines")


def _rest(out: str, samples: list | None = None) -> list[str]:
    """Words of the lines of ``out`` that are not DFRL_SAMPLE lines."""
    kept = []
    for line in out.splitlines():
        sample = parse_sample(line)
        if sample is None:
            kept += line.split()
        elif samples is not None:
            samples.append(sample)
    return kept


def _finish(p: subprocess.Popen, text: str = "") -> str:
    """Send ``text``, close stdin and read the rest of stdout through ``p.stdout`` itself:
    ``communicate`` reads the pipe beneath it and would lose lines ``readline`` had already
    buffered (a sample written right after a progress line, say). A node that does not
    end within 30 s is killed, so the read is bounded."""
    timer = threading.Timer(30.0, p.kill)
    timer.start()
    try:
        p.stdin.write(text)
        p.stdin.close()
        out = p.stdout.read()
        p.wait(timeout=30)
    finally:
        timer.cancel()
    return out


def test_async_node_trains_then_waits_for_stdin(tmp_path: Path) -> None:
    p = _start(tmp_path, iterations=120, progress_every=50, grace_s=30.0)
    first = p.stdout.readline().split()
    assert first[:3] == ["DFRL_NODE", "r7", "127.0.0.1"] and int(first[3]) > 0
    samples: list = []
    assert _line(p, samples) == ["DFRL_PROGRESS", "r7", "50"]
    assert _line(p, samples) == ["DFRL_PROGRESS", "r7", "100"]
    assert _line(p, samples) == ["DFRL_PROGRESS", "r7", "120"]
    time.sleep(0.3)
    assert p.poll() is None  # lingers, serving, until stdin closes
    out = _finish(p)
    assert _rest(out, samples) == ["DFRL_DONE", "r7", "120", "0"]
    # the pose and the curves now and then (here: the first progress line and the end)
    assert samples[0].iteration == 50 and samples[-1].iteration == 120
    assert all(s.robot == "r7" and -1.0 < s.x < 1.0 and -1.0 < s.y < 1.0 for s in samples)
    assert p.returncode == 0
    with open(tmp_path / "metrics_r7.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert [int(r["iteration"]) for r in rows] == list(range(1, 121))
    assert set(rows[0]) == {"robot", "iteration", "q_sum", "cumulative_reward", "collisions"}
    assert (tmp_path / "tables" / "r7.npy").is_file()
    assert (tmp_path / "shares_r7.csv").read_text().startswith("robot,share_index,")


def test_sync_node_stops_at_a_boundary_when_told(tmp_path: Path) -> None:
    p = _start(tmp_path, iterations=1000, respite=40, mode="sync", progress_every=0)
    assert p.stdout.readline().startswith("DFRL_NODE r7")
    time.sleep(1.0)  # waits at iteration 40 for a share
    assert p.poll() is None
    out = _finish(p, "stop\n")
    assert _rest(out)[-4:] == ["DFRL_DONE", "r7", "40", "0"]
    with open(tmp_path / "metrics_r7.csv", newline="") as fh:
        assert len(list(csv.DictReader(fh))) == 40


def test_bad_config_exits_2(tmp_path: Path) -> None:
    path = tmp_path / "node.json"
    path.write_text(json.dumps({"robot": "r1", "out_dir": str(tmp_path), "colour": "red"}))
    p = subprocess.run(
        [sys.executable, "-m", "dfrl.experiments.robot_host", "--config", str(path)],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=60,
    )
    assert p.returncode == 2 and "colour" in p.stderr


@pytest.mark.parametrize("rtf", [10.0])
def test_real_time_factor_paces_the_loop(tmp_path: Path, rtf: float) -> None:
    p = _start(tmp_path, iterations=50, rtf=rtf, progress_every=0, grace_s=0.0)
    assert p.stdout.readline().startswith("DFRL_NODE")
    t0 = time.monotonic()
    out = _finish(p)
    assert "DFRL_DONE r7 50" in out
    assert time.monotonic() - t0 >= 50 * 0.064 / rtf * 0.95


def _paced_seconds(tmp_path: Path, **kw) -> float:
    """Wall seconds between the progress lines of iterations 5 and 25 at rtf 10."""
    tmp_path.mkdir()
    p = _start(tmp_path, iterations=25, rtf=10.0, progress_every=5, grace_s=0.0, **kw)
    try:
        assert p.stdout.readline().startswith("DFRL_NODE")
        assert _line(p) == ["DFRL_PROGRESS", "r7", "5"]
        t0 = time.monotonic()
        for i in (10, 15, 20, 25):
            assert _line(p) == ["DFRL_PROGRESS", "r7", str(i)]
        elapsed = time.monotonic() - t0
        out = _finish(p)
        assert "DFRL_DONE r7 25" in out
        return elapsed
    finally:
        if p.poll() is None:
            p.kill()
            p.wait(timeout=10)


def test_pace_follows_the_trainers_control_dt(tmp_path: Path) -> None:
    """20 iterations at rtf 10: 20 * control_dt / 10 s (0.128 s at the default 64 ms,
    0.512 s at 256 ms)."""
    default = _paced_seconds(tmp_path / "a")
    slow = _paced_seconds(tmp_path / "b", trainer={"sim": {"control_dt": 0.256}})
    assert 20 * 0.064 / 10 * 0.95 <= default < 0.45, default
    assert slow >= 20 * 0.256 / 10 * 0.95, slow


def test_node_with_stdin_at_eof_from_the_start_runs_every_iteration(tmp_path: Path) -> None:
    """Started with stdin at end of file (< /dev/null), the node is not told to stop at
    iteration 50: stdin is no channel then."""
    cfg = RobotConfig(
        robot="r7", out_dir=str(tmp_path), arena="r2", iterations=160, progress_every=0, grace_s=0.0
    )
    path = tmp_path / "node.json"
    path.write_text(json.dumps(cfg.to_dict()))
    p = subprocess.run(
        [sys.executable, "-m", "dfrl.experiments.robot_host", "--config", str(path)],
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=120,
    )
    assert p.returncode == 0, p.stderr
    assert _rest(p.stdout)[-4:] == ["DFRL_DONE", "r7", "160", "0"]
    with open(tmp_path / "metrics_r7.csv", newline="") as fh:
        assert len(list(csv.DictReader(fh))) == 160
    assert (tmp_path / "checkpoint" / "r7.npy").is_file()


def test_a_robot_whose_driver_died_stops_cleanly_and_saves_its_tables(tmp_path: Path) -> None:
    # the driver killed: its end of our stdout pipe and of our stdin close at once
    p = _start(tmp_path, iterations=200_000, progress_every=50, events=False, grace_s=0.0)
    assert _line(p)[0] == "DFRL_NODE"
    assert _line(p)[0] == "DFRL_PROGRESS"  # training
    p.stdout.close()  # the reader is gone ...
    p.stdin.close()  # ... and so is the writer
    try:
        code = p.wait(timeout=60)
    finally:
        if p.poll() is None:
            p.kill()
    err = p.stderr.read()
    assert code == 0, err
    assert "BrokenPipeError" not in err and "Traceback" not in err, err
    assert (tmp_path / "tables" / "r7.npy").exists()  # stopped early, tables saved
    assert (tmp_path / "metrics_r7.csv").exists()
