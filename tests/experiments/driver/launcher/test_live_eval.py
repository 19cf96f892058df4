"""Greedy evaluations while the robots learn (``eval_every``, ``eval_steps``): rows in
``eval_<robot>.csv`` and ``live_evaluations.csv``, ``eval`` events for the live view, a line per
robot in the summary, from local robots and from a robot on a ``dfrl robot`` service; and the
control: the same run without evaluations learns byte for byte the same."""

from __future__ import annotations

import csv
import json
import math
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from dfrl.experiments.driver.config import ExperimentConfig, RobotSpec
from dfrl.experiments.driver.launcher import run
from dfrl.experiments.robot_host.evaluate import EVAL_FIELDS, eval_seed
from dfrl.experiments.robot_host.lines import Evaluation, ProtocolLines, parse_eval
from dfrl.experiments.tokens import env_with_tokens
from dfrl.experiments.driver.launcher.events import EVENTS_FILE
from dfrl.experiments.tools.view import EventSource

from .helpers import diagnose, small_config
from dfrl.experiments.processes import find_swipl

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")


def _rows(path: Path) -> list[dict[str, str]]:
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _events(out: Path, kind: str) -> list[dict]:
    events = [json.loads(x) for x in (out / EVENTS_FILE).read_text().splitlines()]
    return [e for e in events if e["kind"] == kind]


def _check_row(r: dict[str, str]) -> None:
    values = {k: float(r[k]) for k in EVAL_FIELDS[4:]}
    assert all(math.isfinite(v) for v in values.values()), r
    assert 0.0 <= values["collisions_per_1000"] <= 1000.0, r
    assert -1.0 <= values["progress"] <= 1.0 and 0.0 <= values["coverage"] <= 1.0, r
    assert values["distance"] >= 0.0 and int(r["steps"]) == 100, r


def test_evaluations_do_not_disturb_training(tmp_path: Path) -> None:
    walls = {}
    for name, kw in (("eval", dict(eval_every=100, eval_steps=100)), ("plain", {})):
        t0 = time.monotonic()
        res = run(
            small_config(2, iterations=300, respite=100, **kw), tmp_path / name, progress=None
        )
        walls[name] = time.monotonic() - t0
        assert res.ok, diagnose(tmp_path / name)
    ev, plain = tmp_path / "eval", tmp_path / "plain"
    print(f"wall time with evaluations {walls['eval']:.2f} s, without {walls['plain']:.2f} s")
    # the control: evaluation never touched the trainers (RNG, environment, table)
    assert (ev / "metrics.csv").read_bytes() == (plain / "metrics.csv").read_bytes()
    saved = sorted(p.relative_to(ev) for p in (ev / "tables").rglob("*") if p.is_file())
    assert saved == sorted(
        p.relative_to(plain) for p in (plain / "tables").rglob("*") if p.is_file()
    )
    assert len(saved) >= 12  # table, visits, json per robot + history
    for rel in saved:
        assert (ev / rel).read_bytes() == (plain / rel).read_bytes(), rel
    for rid in ("r1", "r2"):
        digests = [[s["digest"] for s in _rows(d / f"shares_{rid}.csv")] for d in (ev, plain)]
        assert digests[0] == digests[1] and len(digests[0]) == 3
    rows = _rows(ev / "live_evaluations.csv")
    assert [(r["robot"], int(r["iteration"])) for r in rows] == [
        (rid, it) for rid in ("r1", "r2") for it in (100, 200, 300)
    ]
    assert [r["arena"] for r in rows] == ["r1"] * 3 + ["r4"] * 3
    for r in rows:
        _check_row(r)
    for rid in ("r1", "r2"):
        assert _rows(ev / f"eval_{rid}.csv") == [r for r in rows if r["robot"] == rid]
    events = _events(ev, "eval")
    for rid in ("r1", "r2"):
        mine = [e for e in events if e["robot"] == rid]
        assert [e["iteration"] for e in mine] == [100, 200, 300], events
        file_rows = [r for r in rows if r["robot"] == rid]
        assert [e["progress"] for e in mine] == [float(r["progress"]) for r in file_rows]
        assert [e["collisions_per_1000"] for e in mine] == [
            float(r["collisions_per_1000"]) for r in file_rows
        ]
    summary = (ev / "summary.md").read_text()
    for rid in ("r1", "r2"):
        last = rows[2 if rid == "r1" else 5]
        assert (
            f"- {rid}: last greedy evaluation (iteration 300, 100 steps): "
            f"{float(last['collisions_per_1000']):.1f} collisions per 1,000 steps"
        ) in summary
    # without eval_every: no file, no event, no summary line
    assert not (plain / "live_evaluations.csv").exists() and not list(plain.glob("eval_*.csv"))
    assert (
        not _events(plain, "eval") and "greedy evaluation" not in (plain / "summary.md").read_text()
    )
    # the view passes them on (its third curve)
    got = [e for e in EventSource(ev).drain() if e["kind"] == "eval"]
    assert len(got) == 6 and {e["robot"] for e in got} == {"r1", "r2"}


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_remote_robot_evaluates_and_its_file_is_gathered(tmp_path: Path) -> None:
    port = _free_port()
    (tmp_path / "svc").mkdir()
    svc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "dfrl.experiments",
            "robot",
            "--host",
            "127.0.0.1",
            "--port",
            str(port),
            "--workdir",
            str(tmp_path / "svc"),
        ],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env_with_tokens([1111]),
    )
    try:
        line = svc.stdout.readline()
        assert "listening on" in line, line + svc.stderr.read()
        cfg = small_config(
            2, iterations=300, respite=100, eval_every=150, eval_steps=100, token=1111
        )  # the remote robot's token
        cfg = cfg.replace(
            robots=(cfg.robots[0], RobotSpec("r2", "r4", robot_host=f"127.0.0.1:{port}"))
        )
        res = run(cfg, tmp_path / "out", progress=None)
        assert res.ok, diagnose(tmp_path / "out")
    finally:
        svc.terminate()
        svc.communicate(timeout=30)
    out = tmp_path / "out"
    assert "eval_r2.csv" in res.gathered["r2"]
    rows = _rows(out / "live_evaluations.csv")
    assert [(r["robot"], int(r["iteration"])) for r in rows] == [
        ("r1", 150),
        ("r1", 300),
        ("r2", 150),
        ("r2", 300),
    ]
    for r in rows:
        _check_row(r)
    events = _events(out, "eval")
    assert [(e["robot"], e["iteration"]) for e in events if e["robot"] == "r2"] == [
        ("r2", 150),
        ("r2", 300),
    ], events
    assert "- r2: last greedy evaluation (iteration 300" in (out / "summary.md").read_text()


def test_eval_line_round_trip_and_seed() -> None:
    class Out:
        text = ""

        def write(self, s: str) -> None:
            self.text += s

        def flush(self) -> None:
            pass

    out = Out()
    ProtocolLines(out, "r3").evaluation(400, 12.0, 0.25, 0.125)  # type: ignore[arg-type]
    assert parse_eval(out.text) == Evaluation("r3", 400, 12.0, 0.25, 0.125)
    for bad in (
        "DFRL_EVAL r3 400 12.0 0.25",
        "DFRL_EVAL r3 x 1 2 3",
        "DFRL_EVAL r3 4 nan 2 3",
        "DFRL_SAMPLE r3 4 1 2 3",
    ):
        assert parse_eval(bad) is None, bad
    quiet = Out()
    silent = ProtocolLines(quiet, "r3", events=False)  # type: ignore[arg-type]
    silent.evaluation(400, 1.0, 0.0, 0.0)
    assert quiet.text == ""
    assert eval_seed(1, 100) == eval_seed(1, 100)
    assert len({eval_seed(s, it) for s in (1, 2) for it in (100, 200)}) == 4
    assert all(0 <= eval_seed(s, 100) < 2**32 for s in (0, 7, 10**9))


def test_bad_eval_options_are_located(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    from dfrl.experiments.cli import main
    from dfrl.experiments.robot_host.config import check_robot_config

    monkeypatch.chdir(tmp_path)
    cfg = {
        "name": "bad",
        "robots": [{"id": "r1", "arena": "r1"}],
        "iterations": 200,
        "respite": 50,
        "mode": "sync",
    }
    for changes, located in (
        ({"eval_every": -1}, "eval_every: must be >= 0, got -1"),
        ({"eval_steps": 0}, "eval_steps: must be >= 1, got 0"),
        ({"eval_every": "100"}, "eval_every: expected an integer, got '100' (a string)"),
        ({"eval_steps": 2.5}, "eval_steps: expected an integer, got 2.5"),
        # a run that would evaluate nothing must not pass for one that did
        ({"eval_every": 500}, "eval_every: 500 is more than the 200 iterations"),
    ):
        path = tmp_path / "cfg.json"
        path.write_text(json.dumps({**cfg, **changes}))
        code = main(["run", str(path)])
        err = capsys.readouterr().err
        assert code == 2, err
        assert located in err and "nothing was started" in err, err
        assert not (tmp_path / "results").exists()
    problems = "\n".join(
        check_robot_config({"robot": "r1", "out_dir": "x", "eval_every": True, "eval_steps": -5})
    )
    assert "eval_every: expected an integer, got True (a boolean)" in problems, problems
    assert "eval_steps: must be >= 1, got -5" in problems, problems
    ok = ExperimentConfig.from_dict({**cfg, "eval_every": 100, "eval_steps": 50})
    assert (ok.eval_every, ok.eval_steps) == (100, 50)
    assert ExperimentConfig.from_dict({**cfg, "eval_every": 200}).eval_every == 200
    default = ExperimentConfig.from_dict(cfg)
    assert (default.eval_every, default.eval_steps) == (0, 500)
