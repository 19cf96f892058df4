"""The page in headless Chromium during a real 2-robot run: the agent moves, the round
counter advances, the curves gain points, and a robot killed with SIGKILL is shown dead.

Chromium and its driver come from Debian's packages (scripts/browser-setup.sh, run here when
they are missing); the test is skipped, saying why, only when they cannot be installed.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import pytest

from dfrl.experiments.driver.launcher.experiment import Launcher
from dfrl.experiments.tools.view import start_view

from ...driver.launcher.helpers import small_config
from .helpers import browser_paths, chrome, finished_run
from dfrl.experiments.processes import find_swipl

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")

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


def test_page_follows_a_run_and_shows_a_killed_robot_dead(
    tmp_path: Path, browser: tuple[str, str]
) -> None:
    out = tmp_path / "run"
    cfg = small_config(2, iterations=2400, respite=100, rtf=10.0, timeout_s=120)
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
            # the kill waits for what the page must have shown by then (round 4, curves that
            # grew in steps), not for a time that assumes an idle machine
            deadline = time.monotonic() + 150
            while time.monotonic() < deadline:
                s = driver.execute_script(SAMPLE)
                samples.append(s)
                grown = len({x["points"] for x in samples}) >= 3
                if killed_at is None and s["round"] >= 4 and grown:
                    pid = launcher.robots()["r2"].status().pid
                    assert pid is not None
                    os.kill(pid, signal.SIGKILL)
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
    assert len(positions) >= 2, positions  # the agent moved between nodes
    assert {"forward", "backward"} & phases, phases
    rounds = [s["round"] for s in samples]
    assert rounds[0] <= 1 and max(rounds) >= 4 and rounds == sorted(rounds)
    points = [s["points"] for s in samples]
    assert points[-1] > points[0] and len(set(points)) >= 3  # the curves grew, in steps
    assert final["stats"]["firstPaintMs"] is not None
    assert (tmp_path / "view.png").stat().st_size > 20_000
    res = box["res"]
    assert "r2" in res.crashed  # the launcher saw the kill too


PAGE = """
const arenas = document.querySelectorAll('#arenas .arena');
const r = document.querySelector('.agent-line .round');
return {robots: document.querySelectorAll('#network .robot').length,
        done: document.querySelectorAll('#network .robot[data-state="done"]').length,
        arenas: arenas.length,
        posed: [...arenas].filter(a => a.dataset.pose).length,
        round: r ? Number(r.dataset.round) : 0,
        points: Number(document.getElementById('chart-q').dataset.points),
        events: Number(document.getElementById('replay').max),
        status: document.getElementById('run-status').dataset.status,
        stats: window.dfrlView.stats};
"""

MOVE = """
const [k, done] = arguments;
const slider = document.getElementById('replay'), stats = window.dfrlView.stats;
const t0 = performance.now(), r0 = stats.renders;
slider.value = String(k);
slider.dispatchEvent(new Event('input'));
(function wait() {
  // the frame that moved the page, then the next one: what the move drew is on screen
  if (stats.renders > r0) requestAnimationFrame(() => done(performance.now() - t0));
  else setTimeout(wait, 5);
})();
"""


def test_page_stays_responsive_for_a_finished_32_robot_run(
    tmp_path: Path, browser: tuple[str, str]
) -> None:
    """``dfrl view`` of a finished 32-robot run as large as a real one (8,000 iterations,
    16 rounds, every hop, two poses a second per robot): the page draws every robot, its
    arena and its pose within a bound, and a replay move across the whole run stays quick."""
    out = tmp_path / "r32"
    finished_run(out, robots=32)
    proc = subprocess.Popen(
        [sys.executable, "-m", "dfrl.experiments", "view", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = proc.stdout.readline()
        found = re.search(r" at (http://\S+) ", line)
        assert found, line + proc.stderr.read()
        driver = chrome(*browser)
        try:
            driver.set_script_timeout(30)
            t0 = time.monotonic()
            driver.get(found.group(1))
            s = driver.execute_script(PAGE)
            while time.monotonic() - t0 < 60:
                if (
                    s["status"] == "finished"
                    and s["robots"] == 32
                    and s["posed"] == 32
                    and s["round"] == 16
                ):
                    break
                time.sleep(0.1)
                s = driver.execute_script(PAGE)
            shown_s = time.monotonic() - t0
            assert (s["robots"], s["arenas"], s["posed"], s["round"]) == (32, 32, 32, 16), s
            assert s["points"] >= 32 * 400 and s["done"] == 32, s
            total = s["events"]
            moves = {}
            for k in (0, total // 2, total):
                moves[k] = driver.execute_async_script(MOVE, k)
                moves[f"{k}-state"] = driver.execute_script(PAGE)
            driver.save_screenshot(str(tmp_path / "view32.png"))
        finally:
            driver.quit()
    finally:
        proc.terminate()
        proc.wait(timeout=10)
    half = moves[f"{total // 2}-state"]
    assert moves["0-state"]["robots"] == 0  # before the first event
    assert 0 < half["round"] < 16 and 0 < half["points"] < s["points"], half
    assert moves[f"{total}-state"]["round"] == 16
    print(
        f"32 robots: all shown after {shown_s:.2f} s; replay moves (ms): "
        f"{[round(moves[k]) for k in (0, total // 2, total)]}"
    )
    assert shown_s < 20.0, shown_s
    assert max(moves[k] for k in (0, total // 2, total)) < 3000, moves


CLONES = """
const marks = [...document.querySelectorAll('#agent-marks .agent-clone')]
  .filter(g => g.getAttribute('visibility') === 'visible');
return {status: document.getElementById('run-status').dataset.status,
        round: Number((document.querySelector('.agent-line .round') || {dataset: {round: 0}})
                      .dataset.round),
        clones: marks.map(g => [g.dataset.robot, g.dataset.phase]).sort(),
        agent: (document.querySelector('#agent-marks .agent') || {dataset: {}}).dataset.robot};
"""


@pytest.mark.parametrize("itinerary", ["tree", "chain"])
def test_a_tree_agents_copies_are_drawn_at_their_robots(
    tmp_path: Path, browser: tuple[str, str], itinerary: str
) -> None:
    """A finished tree run's page draws the last round's copies, one hollow mark at every
    robot but the root, having written their tables; the agent's own mark stays at the root.
    The control, the same run as a chain, draws no copy."""
    out = tmp_path / itinerary
    cfg = small_config(3, iterations=300, respite=100, itinerary=itinerary)
    from dfrl.experiments.driver.launcher import run

    assert run(cfg, out, progress=None).ok
    with start_view(out) as view:
        driver = chrome(*browser)
        try:
            driver.get(view.url)
            deadline = time.monotonic() + 60
            s = driver.execute_script(CLONES)
            while time.monotonic() < deadline and (s["status"] != "finished" or s["round"] < 3):
                time.sleep(0.1)
                s = driver.execute_script(CLONES)
            time.sleep(0.5)  # the frames after the last events
            s = driver.execute_script(CLONES)
        finally:
            driver.quit()
    assert s["status"] == "finished" and s["round"] == 3, s
    if itinerary == "chain":
        assert s["clones"] == [], s
        return
    assert s["clones"] == [["r2", "backward"], ["r3", "backward"]], s
    assert s["agent"] == "r1", s
