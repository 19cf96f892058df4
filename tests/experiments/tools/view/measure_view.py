"""Measurements of the live view (not a test): ``python -m tests.experiments.tools.view.measure_view``.

* ``page``: a synthetic 32-robot results folder (8,000 iterations, respite 500, 16 rounds),
  finished and then written live; time to first paint in headless Chromium and the page's
  handling time per event and per redraw.
* ``screenshot PATH``: the README's picture (``docs/view.png``), a live demo in Chromium;
* ``overhead [PAIRS]``: the demo config (5 robots, sync, same seed) run with the launcher
  directly, alternately without and with ``start_view`` on its folder and a browser attached
  (started, and settled after its start-up, before the run begins); medians of PAIRS pairs
  (default 4).
"""

from __future__ import annotations

import json
import os
import resource
import random
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

from dfrl.experiments.tools.view import start_view

from .helpers import append, browser_paths, chrome, round_line, write_run

STATS = "return window.dfrlView.stats"


def synthetic(
    out: Path,
    robots: int = 32,
    iterations: int = 8000,
    respite: int = 500,
    upto: int | None = None,
    t0: float | None = None,
) -> None:
    """Metrics, shares and the round log of a fake sync run up to iteration ``upto``."""
    ids = tuple(f"r{i + 1}" for i in range(robots))
    if not (out / "config.json").exists():
        write_run(out, ids, iterations, respite)
    upto = iterations if upto is None else upto
    rng = random.Random(1)
    t0 = time.time() if t0 is None else t0
    done = _done.get(out, 0)
    for i, rid in enumerate(ids):
        q = [
            f"{rid},{k},{k * 0.01 + rng.random():.6f},{k * 0.02:.6f},0\n"
            for k in range(done + 1, upto + 1)
        ]
        append(out / f"metrics_{rid}.csv", "".join(q))
    for k in range(done // respite + 1, upto // respite + 1):
        t = t0 + k
        for i, rid in enumerate(ids):
            append(
                out / f"shares_{rid}.csv",
                f"{rid},{k},{k * respite},{t + 0.5 - i * 0.01},d,{k},fed_qlearning,1\n",
            )
        append(out / "rounds_fed_qlearning.log", round_line(k, list(ids), t))
    _done[out] = upto


_done: dict[Path, int] = {}


def page(browser: tuple[str, str]) -> dict[str, Any]:
    res: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "done"
        synthetic(out)
        (out / "summary.md").write_text("done\n")
        t = time.perf_counter()
        view = start_view(out)
        for _ in range(3000):  # until the first read is done (30 s)
            if any(e["kind"] == "run_end" for e in view.source.events):
                break
            time.sleep(0.01)
        res["finished_drain_s"] = round(time.perf_counter() - t, 3)
        res["finished_events"] = len(view.source.events)
        drv = chrome(*browser)
        try:
            t = time.perf_counter()
            drv.get(view.url)
            for _ in range(300):
                s = drv.execute_script(STATS)
                if s["firstPaintMs"] is not None and s["received"] >= res["finished_events"]:
                    break
                time.sleep(0.05)
            res["finished_first_paint_ms"] = round(s["firstPaintMs"], 1)
            res["finished_all_events_ms"] = round((time.perf_counter() - t) * 1000, 1)
            res["finished_apply_us_per_event"] = round(1000 * s["applyMs"] / s["received"], 2)
            res["finished_render_ms"] = round(s["renderMs"] / max(1, s["renders"]), 2)
            res["points_drawn"] = drv.execute_script(
                "return Number(document.getElementById('chart-q').dataset.points)"
            )
        finally:
            drv.quit()
            view.close()
        # live: the same run written 100 iterations at a time, 10 times a second
        out = Path(tmp) / "live"
        synthetic(out, upto=0)
        view = start_view(out)
        drv = chrome(*browser)
        try:
            drv.get(view.url)
            time.sleep(1.0)
            t = time.perf_counter()
            for k in range(100, 8001, 100):
                synthetic(out, upto=k)
                time.sleep(0.1)
            time.sleep(1.0)
            s = drv.execute_script(STATS)
            res["live_s"] = round(time.perf_counter() - t, 2)
            res["live_events"] = s["received"]
            res["live_apply_us_per_event"] = round(1000 * s["applyMs"] / s["received"], 2)
            res["live_render_ms"] = round(s["renderMs"] / max(1, s["renders"]), 2)
            res["live_renders"] = s["renders"]
            res["live_first_paint_ms"] = round(s["firstPaintMs"], 1)
            t = time.perf_counter()
            drv.execute_script("return 1")
            res["live_script_roundtrip_ms"] = round((time.perf_counter() - t) * 1000, 1)
        finally:
            drv.quit()
            view.close()
    return res


def _tree_cpu(root: int) -> float:
    """CPU seconds (user + system) of process ``root`` and its descendants, from /proc."""
    parent: dict[int, int] = {}
    cpu: dict[int, float] = {}
    tick = os.sysconf("SC_CLK_TCK")
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            fields = open(f"/proc/{d}/stat").read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        parent[int(d)] = int(fields[1])
        cpu[int(d)] = (int(fields[11]) + int(fields[12]) + int(fields[13]) + int(fields[14])) / tick
    total, todo = 0.0, [root]
    while todo:
        p = todo.pop()
        total += cpu.get(p, 0.0)
        todo += [c for c, pp in parent.items() if pp == p]
    return total


def _cpu_self_children() -> float:
    s, c = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return s.ru_utime + s.ru_stime + c.ru_utime + c.ru_stime


def settle(pid: int, quiet_s: float = 0.02, every_s: float = 0.5, limit_s: float = 15.0) -> float:
    """Wait until the process tree of ``pid`` spends less than ``quiet_s`` CPU seconds in
    ``every_s`` (a browser that finished starting up); return the seconds waited."""
    t0 = time.perf_counter()
    before = _tree_cpu(pid)
    while time.perf_counter() - t0 < limit_s:
        time.sleep(every_s)
        now = _tree_cpu(pid)
        if now - before < quiet_s:
            break
        before = now
    return time.perf_counter() - t0


def demo_once(
    with_view: bool, browser: tuple[str, str] | None, out: Path, cpu: dict[str, float] | None = None
) -> float:
    from dfrl.experiments.driver.config import ExperimentConfig, resolve_config
    from dfrl.experiments.driver.launcher.experiment import run

    cfg = ExperimentConfig.load(resolve_config("demo"))
    view = drv = None
    if with_view:
        view = start_view(out, fresh=True)
        assert browser is not None
        drv = chrome(*browser)
        drv.get(view.url)
        # Chromium spends about 0.7 s of CPU finishing its start-up after the first page
        # (about:blank too): that is starting a browser, not serving the view
        settle(drv.service.process.pid)
    try:
        b0 = _tree_cpu(drv.service.process.pid) if drv is not None else 0.0
        c0 = _cpu_self_children()
        t = time.perf_counter()
        res = run(cfg, out, progress=None)
        wall = time.perf_counter() - t
        assert res.ok
        if cpu is not None:
            cpu["run"] = _cpu_self_children() - c0  # launcher, robots, console (+ view)
        if drv is not None:
            s = drv.execute_script(STATS)
            assert s["received"] > 100, s
            if cpu is not None:
                cpu["browser"] = _tree_cpu(drv.service.process.pid) - b0
                cpu["view_poll"] = view.poll_cpu_s
    finally:
        if drv is not None:
            drv.quit()
        if view is not None:
            view.close()
    return wall


def overhead(browser: tuple[str, str], pairs: int = 4) -> dict[str, Any]:
    off, on, cpu_off, cpu_on = [], [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for k in range(pairs):
            c1: dict[str, float] = {}
            c2: dict[str, float] = {}
            off.append(demo_once(False, None, Path(tmp) / f"off{k}", c1))
            on.append(demo_once(True, browser, Path(tmp) / f"on{k}", c2))
            cpu_off.append(c1)
            cpu_on.append(c2)
        same = all(
            (Path(tmp) / f"off{k}/metrics.csv").read_bytes()
            == (Path(tmp) / f"on{k}/metrics.csv").read_bytes()
            for k in range(pairs)
        )
    m_off, m_on = statistics.median(off), statistics.median(on)
    return {
        "without_view_s": [round(x, 2) for x in off],
        "with_view_s": [round(x, 2) for x in on],
        "median_without_s": round(m_off, 2),
        "median_with_s": round(m_on, 2),
        "overhead_pct": round(100 * (m_on - m_off) / m_off, 1),
        "same_metrics": same,
        "cpu_run_without_s": [round(c["run"], 2) for c in cpu_off],
        "cpu_run_with_view_s": [round(c["run"], 2) for c in cpu_on],
        "cpu_browser_s": [round(c["browser"], 2) for c in cpu_on],
        "cpu_view_poll_s": [round(c["view_poll"], 3) for c in cpu_on],
        "cpu_overhead_pct": round(
            100
            * statistics.median(
                (c2["browser"] + c2["run"] - c1["run"]) / c1["run"]
                for c1, c2 in zip(cpu_off, cpu_on)
            ),
            1,
        ),
        "load_before": os.getloadavg(),
    }


def screenshot(browser: tuple[str, str], path: Path, at_round: int = 10) -> dict[str, Any]:
    """The README's picture: the page during a live demo run (5 robots), taken by the test
    set-up's Chromium once the agent has done ``at_round`` rounds."""
    from dfrl.experiments.driver.config import ExperimentConfig, resolve_config
    from dfrl.experiments.driver.launcher.experiment import run

    cfg = ExperimentConfig.load(resolve_config("demo"))
    box: dict[str, Any] = {}
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "demo"
        with start_view(out, fresh=True) as view:
            drv = chrome(*browser, height=900)
            try:
                drv.get(view.url)
                thread = threading.Thread(
                    target=lambda: box.update(res=run(cfg, out, progress=None)), daemon=True
                )
                thread.start()
                for _ in range(1200):  # 120 s at most
                    rnd = drv.execute_script(
                        "const r = document.querySelector('.agent-line .round');"
                        "return r ? Number(r.dataset.round) : 0"
                    )
                    if rnd >= at_round or not thread.is_alive():
                        break
                    time.sleep(0.1)
                time.sleep(0.6)  # the frame after that one
                drv.save_screenshot(str(path))
            finally:
                drv.quit()
            thread.join(120)
    return {"screenshot": str(path), "round": rnd, "ok": bool(box.get("res") and box["res"].ok)}


def main(argv: list[str]) -> int:
    paths = browser_paths()
    if isinstance(paths, str):
        print(paths, file=sys.stderr)
        return 1
    what = argv[1:] or ["page", "overhead"]
    out = {}
    if "page" in what:
        out["page"] = page(paths)
    if "screenshot" in what:
        out["screenshot"] = screenshot(paths, Path(what[what.index("screenshot") + 1]))
    if "overhead" in what:
        pairs = [int(a) for a in what if a.isdigit()]
        out["overhead"] = overhead(paths, *pairs[:1])
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
