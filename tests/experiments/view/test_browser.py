"""The page in headless Chromium during a real 2-robot run: the agent moves, the round
counter advances, the curves gain points, and a robot killed with SIGKILL is shown dead.

Chromium and its driver come from Debian's packages (scripts/browser-setup.sh, run here when
they are missing); the test is skipped, saying why, only when they cannot be installed.
"""
from __future__ import annotations

import os
import shutil
import signal
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from dfrl.experiments.launcher.run import Launcher
from dfrl.experiments.view import start_view

from ..launcher.helpers import small_config
from .helpers import browser_paths, chrome

pytestmark = pytest.mark.skipif(shutil.which("swipl") is None, reason="needs swipl")

SAMPLE = """
const a = document.querySelector('#agent-marks .agent');
const r = document.querySelector('.agent-line .round');
const robots = {};
for (const g of document.querySelectorAll('#network .robot'))
  robots[g.dataset.robot] = g.dataset.state;
return {agent: a ? [a.dataset.robot, a.dataset.phase, a.dataset.x, a.dataset.y,
                    a.dataset.moves] : null,
        round: r ? Number(r.dataset.round) : 0,
        points: Number(document.getElementById('chart-q').dataset.points),
        robots: robots,
        stats: window.dfrlView.stats};
"""


@pytest.fixture(scope="module")
def browser() -> tuple[str, str]:
    paths = browser_paths()
    if isinstance(paths, str):
        pytest.skip(f"no headless Chromium: {paths}")
    return paths


def test_page_follows_a_run_and_shows_a_killed_robot_dead(tmp_path: Path,
                                                          browser: tuple[str, str]) -> None:
    out = tmp_path / "run"
    cfg = small_config(2, iterations=1200, respite=100, rtf=10.0, timeout_s=120)
    launcher = Launcher(cfg, out, progress=None)
    box: dict[str, Any] = {}

    def target() -> None:
        try:
            box["res"] = launcher.run()
        except BaseException as exc:  # noqa: BLE001
            box["exc"] = exc

    samples: list[dict[str, Any]] = []
    killed_at: float | None = None
    with start_view(out, fresh=True) as view:
        driver = chrome(*browser)
        try:
            driver.get(view.url)
            thread = threading.Thread(target=target, daemon=True)
            thread.start()
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline:
                s = driver.execute_script(SAMPLE)
                samples.append(s)
                if killed_at is None and s["round"] >= 4:
                    child = launcher.state.children["r2"]
                    os.kill(child.proc.pid, signal.SIGKILL)
                    killed_at = time.monotonic()
                if killed_at is not None and s["robots"].get("r2") == "dead":
                    break
                time.sleep(0.2)
            time.sleep(0.5)
            driver.save_screenshot(str(tmp_path / "view.png"))
            final = driver.execute_script(SAMPLE)
        finally:
            driver.quit()
        thread.join(90)
    assert "exc" not in box, box
    assert killed_at is not None, samples[-1:]
    assert final["robots"].get("r2") == "dead", final
    positions = {tuple(s["agent"][2:4]) for s in samples if s["agent"]}
    phases = {s["agent"][1] for s in samples if s["agent"]}
    assert len(positions) >= 2, positions                 # the agent moved between nodes
    assert {"forward", "backward"} & phases, phases
    rounds = [s["round"] for s in samples]
    assert rounds[0] <= 1 and max(rounds) >= 4 and rounds == sorted(rounds)
    points = [s["points"] for s in samples]
    assert points[-1] > points[0] and len(set(points)) >= 3   # the curves grew, in steps
    assert final["stats"]["firstPaintMs"] is not None
    assert (tmp_path / "view.png").stat().st_size > 20_000
    res = box["res"]
    assert "r2" in res.crashed                            # the launcher saw the kill too
