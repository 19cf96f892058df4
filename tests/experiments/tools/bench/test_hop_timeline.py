"""The hop probes (platform_pl/hop_probe.pl) and ``dfrl bench migrate --timeline``."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

from dfrl.experiments.processes import find_swipl
from dfrl.experiments.tools.bench import hop_timeline, migrate

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")

REPO = Path(__file__).resolve().parents[4]


def _agent_move_body(probe: str | None) -> str:
    """migration:agent_move/3's compiled body, listed by a fresh swipl (DFRL_HOP_PROBE=probe)."""
    env = {k: v for k, v in os.environ.items() if k != migrate.PROBE_ENV}
    if probe is not None:
        env[migrate.PROBE_ENV] = probe
    done = subprocess.run(
        [
            find_swipl(),
            "-q",
            "-g",
            "use_module(platform_pl/tartarus), clause(migration:agent_move(_,_,_), B), "
            "portray_clause(B), halt",
        ],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


def test_probes_are_compiled_in_only_when_asked() -> None:
    assert "hop_probe" not in _agent_move_body(None)
    assert "hop_probe" not in _agent_move_body("0")
    # control: with the variable set, the same clause stamps its point
    assert "hop_probe:stamp(move_called)" in _agent_move_body("/tmp")


def _at(points: list[hop_timeline.Point]) -> dict[str, float]:
    return {p.point: p.at_ms for p in points}


def test_timeline_follows_the_hand_over_in_causal_order() -> None:
    run = hop_timeline.measure(0, 12, warmup=2)
    at = _at(run.points)
    expected = set(hop_timeline.SOURCE_POINTS) | {
        "frame_arrived (transfer)",
        "frame_read (transfer)",
        "checked",
        "installed",
        "staged",
        "replied (transfer)",
        "frame_arrived (commit)",
        "frame_read (commit)",
        "activated",
        "dispatched",
        "run_started",
        "bounds_entering",
        "handler_called",
    }
    assert expected <= set(at), sorted(expected - set(at))
    assert all(p.hops >= 5 for p in run.points)
    chains = [
        # one thread each: stamped in this order
        ["move_called", "prepared", "transfer_sent", "answer_read", "committed", "commit_sent"],
        [
            "frame_arrived (transfer)",
            "frame_read (transfer)",
            "checked",
            "installed",
            "staged",
            "replied (transfer)",
            "frame_arrived (commit)",
            "frame_read (commit)",
            "activated",
            "dispatched",
        ],
        ["run_started", "bounds_entering", "handler_called"],
        # across processes and threads: a frame is read after it was begun, an answer after
        # the request was handled, the agent started after it was activated
        ["prepared", "frame_arrived (transfer)"],
        ["staged", "answer_read"],
        ["committed", "frame_arrived (commit)"],
        ["activated", "run_started"],
    ]
    for chain in chains:
        times = [at[p] for p in chain]
        assert times == sorted(times), list(zip(chain, times))
    # the steps add up to the last point; the handler's start is where the benchmark's own
    # timer stops, so it comes at about the hop's median
    assert sum(p.step_ms for p in run.points) == pytest.approx(run.points[-1].at_ms)
    assert at["handler_called"] <= run.median_ms * 1.5 + 0.5


def test_timeline_of_no_stamps_is_empty_and_a_bad_line_is_located(tmp_path: Path) -> None:
    for role in ("home", "peer"):
        (tmp_path / f"{role}.probe").write_text("")
    assert hop_timeline.timeline(tmp_path) == []
    (tmp_path / "home.probe").write_text("move_called\n")
    with pytest.raises(ValueError, match="home.probe:1"):
        hop_timeline.timeline(tmp_path)


def test_timeline_on_the_command_line(capsys: pytest.CaptureFixture[str]) -> None:
    from dfrl.experiments.cli import main

    assert (
        main(
            [
                "bench",
                "migrate",
                "--floats",
                "1000",
                "--hops",
                "6",
                "--warmup",
                "1",
                "--timeline",
                "--json",
            ]
        )
        == 0
    )
    row = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    points = [p["point"] for p in row["timeline"]["points"]]
    assert points[0] == "move_called" and "handler_called" in points
    assert main(["bench", "migrate", "--floats", "0", "--hops", "4", "--timeline"]) == 0
    assert "installed" in capsys.readouterr().out
    assert main(["bench", "migrate", "--floats", "0", "--timeline", "--against", "/x"]) == 2
