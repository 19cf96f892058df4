"""Helpers of the view tests: a server-sent-events reader, results folders written by hand,
and headless Chromium (installed by scripts/browser-setup.sh when missing)."""
from __future__ import annotations

import http.client
import json
import os
import shutil
import subprocess
import time
from pathlib import Path
from typing import Any
from urllib.parse import urlparse

from dfrl.experiments.view.server import HEARTBEAT_S

ROOT = Path(__file__).resolve().parents[3]


def read_stream(url: str, until: Any, timeout: float = 30.0) -> list[dict[str, Any]]:
    """Events of ``URL/events`` until ``until(events)`` is true or ``timeout`` passed."""
    u = urlparse(url)
    # longer than the server's keep-alive period: a read never times out on a live stream
    conn = http.client.HTTPConnection(u.hostname, u.port, timeout=HEARTBEAT_S + 5.0)
    conn.request("GET", "/events", headers={"Accept": "text/event-stream"})
    resp = conn.getresponse()
    assert resp.status == 200 and resp.getheader("Content-Type") == "text/event-stream"
    events: list[dict[str, Any]] = []
    deadline = time.monotonic() + timeout
    try:
        while time.monotonic() < deadline and not until(events):
            line = resp.fp.readline()
            if not line:
                break                                 # the server closed the stream
            if line.startswith(b"data: "):
                events += json.loads(line[6:])
    finally:
        conn.close()
    return events


def write_run(out: Path, robots: tuple[str, ...] = ("r1", "r2"), iterations: int = 200,
              respite: int = 50) -> None:
    """A results folder as a sync run leaves it before its first round."""
    out.mkdir(parents=True, exist_ok=True)
    arenas = ["r1", "r4", "r2", "r3", "r5"]
    (out / "config.json").write_text(json.dumps({
        "name": "hand", "iterations": iterations, "respite": respite, "mode": "sync",
        "seed": 1, "robots": [{"id": r, "arena": arenas[i % 5]} for i, r in enumerate(robots)]}))
    (out / "nodes.json").write_text(json.dumps({
        "token": 1, "console": ["127.0.0.1", 1],
        "nodes": [{"robot": r, "algo": "qlearning", "arena": arenas[i % 5], "host": "10.0.0.1",
                   "port": 7000 + i, "pid": None, "node": f"10.0.0.1:{7000 + i}",
                   "joined": False} for i, r in enumerate(robots)],
        "agents": [{"name": "fed_qlearning", "algo": "qlearning", "method": "average",
                    "rounds": -(-iterations // respite), "rounds_log": "x",
                    "itinerary": [{"host": "10.0.0.1", "port": 7000 + i, "robot": r}
                                  for i, r in enumerate(robots)]}]}))
    for r in robots:
        (out / f"metrics_{r}.csv").write_text("robot,iteration,q_sum,cumulative_reward,collisions\n")
        (out / f"shares_{r}.csv").write_text(
            "robot,share_index,iteration,wall_time,digest,round,agent,epoch\n")


def append(path: Path, text: str) -> None:
    with open(path, "a", encoding="utf-8") as fh:
        fh.write(text)


def round_line(rnd: int, visited: list[str], t: float, method: str = "average",
               skipped: tuple[str, ...] = ()) -> str:
    return json.dumps({"event": "round", "agent": "fed_qlearning", "round": rnd,
                       "start": t, "end": t + 0.1, "hops": 2 * len(visited) - 2, "bytes": 10,
                       "method": method, "visited": visited, "epoch": 1, "retries": 0,
                       "skipped": [{"robot": s, "reason": "connection refused"}
                                   for s in skipped]}) + "\n"


def hop_order(events: list[dict[str, Any]], agent: str, rnd: int) -> list[tuple[str, str]]:
    return [(e["phase"], e["robot"]) for e in events
            if e["kind"] == "hop" and e["agent"] == agent and e["round"] == rnd]


def canonical(visited: list[str]) -> list[tuple[str, str]]:
    return [("forward", r) for r in visited] + [("backward", r) for r in reversed(visited)]


def browser_paths() -> tuple[str, str] | str:
    """(chromium, chromedriver), installing them when missing; or why they cannot be had."""
    def found() -> tuple[str | None, str | None]:
        drv = shutil.which("chromedriver")
        if drv is None and os.access("/usr/lib/chromium/chromedriver", os.X_OK):
            drv = "/usr/lib/chromium/chromedriver"
        return shutil.which("chromium") or shutil.which("chromium-browser"), drv

    browser, driver = found()
    try:
        import selenium  # noqa: F401
        have_selenium = True
    except ImportError:
        have_selenium = False
    if browser is None or driver is None or not have_selenium:
        setup = subprocess.run(["bash", str(ROOT / "scripts" / "browser-setup.sh")],
                               capture_output=True, text=True, timeout=900)
        if setup.returncode != 0:
            return f"scripts/browser-setup.sh failed: {setup.stderr.strip()[-300:]}"
        browser, driver = found()
    if browser is None or driver is None:
        return "chromium or chromedriver not installed"
    try:
        import selenium  # noqa: F401, F811
    except ImportError:
        return "selenium is not importable (pip install 'selenium>=4.10')"
    return browser, driver


def chrome(browser: str, driver: str, width: int = 1400, height: int = 1000) -> Any:
    """A headless Chromium driven by selenium, with the driver from Debian (nothing
    downloaded: the driver's path is given)."""
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    opts = Options()
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                f"--window-size={width},{height}", "--no-first-run"):
        opts.add_argument(arg)
    opts.binary_location = browser
    return webdriver.Chrome(service=Service(driver), options=opts)
