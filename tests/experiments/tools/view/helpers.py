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

from dfrl.experiments.tools.view.server import HEARTBEAT_S

ROOT = Path(__file__).resolve().parents[4]


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
                break  # the server closed the stream
            if line.startswith(b"data: "):
                events += json.loads(line[6:])
    finally:
        conn.close()
    return events


def write_run(
    out: Path, robots: tuple[str, ...] = ("r1", "r2"), iterations: int = 200, respite: int = 50
) -> None:
    """A results folder as a sync run leaves it before its first round."""
    out.mkdir(parents=True, exist_ok=True)
    arenas = ["r1", "r4", "r2", "r3", "r5"]
    (out / "config.json").write_text(
        json.dumps(
            {
                "name": "hand",
                "iterations": iterations,
                "respite": respite,
                "mode": "sync",
                "seed": 1,
                "robots": [{"id": r, "arena": arenas[i % 5]} for i, r in enumerate(robots)],
            }
        )
    )
    (out / "nodes.json").write_text(
        json.dumps(
            {
                "token": 1,
                "console": ["127.0.0.1", 1],
                "nodes": [
                    {
                        "robot": r,
                        "algo": "qlearning",
                        "arena": arenas[i % 5],
                        "host": "10.0.0.1",
                        "port": 7000 + i,
                        "pid": None,
                        "robot_host": f"10.0.0.1:{7000 + i}",
                        "joined": False,
                    }
                    for i, r in enumerate(robots)
                ],
                "agents": [
                    {
                        "name": "fed_qlearning",
                        "algo": "qlearning",
                        "method": "average",
                        "rounds": -(-iterations // respite),
                        "rounds_log": "x",
                        "itinerary": [
                            {"host": "10.0.0.1", "port": 7000 + i, "robot": r}
                            for i, r in enumerate(robots)
                        ],
                    }
                ],
            }
        )
    )
    for r in robots:
        (out / f"metrics_{r}.csv").write_text(
            "robot,iteration,q_sum,cumulative_reward,collisions\n"
        )
        (out / f"shares_{r}.csv").write_text(
            "robot,share_index,iteration,wall_time,digest,round,agent,epoch\n"
        )


def append(path: Path, text: str) -> None:
    with open(path, "a", encoding="utf-8") as fh:
        fh.write(text)


def round_line(
    rnd: int, visited: list[str], t: float, method: str = "average", skipped: tuple[str, ...] = ()
) -> str:
    return (
        json.dumps(
            {
                "event": "round",
                "agent": "fed_qlearning",
                "round": rnd,
                "start": t,
                "end": t + 0.1,
                "hops": 2 * len(visited) - 2,
                "bytes": 10,
                "method": method,
                "visited": visited,
                "epoch": 1,
                "retries": 0,
                "skipped": [{"robot": s, "reason": "connection refused"} for s in skipped],
            }
        )
        + "\n"
    )


def hop_order(events: list[dict[str, Any]], agent: str, rnd: int) -> list[tuple[str, str]]:
    return [
        (e["phase"], e["robot"])
        for e in events
        if e["kind"] == "hop" and e["agent"] == agent and e["round"] == rnd
    ]


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
        setup = subprocess.run(
            ["bash", str(ROOT / "scripts" / "browser-setup.sh")],
            capture_output=True,
            text=True,
            timeout=900,
        )
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
    for arg in (
        "--headless=new",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        f"--window-size={width},{height}",
        "--no-first-run",
    ):
        opts.add_argument(arg)
    opts.binary_location = browser
    return webdriver.Chrome(service=Service(driver), options=opts)


def finished_run(
    out: Path, robots: int = 32, iterations: int = 8000, respite: int = 500, seconds: float = 80.0
) -> None:
    """A finished sync run of ``robots`` robots, as large as a real one: every metrics row,
    the shares, the round log, and an ``events.jsonl`` with every hop and two poses a second
    per robot (what the launcher writes), over ``seconds`` of run time."""
    import random

    ids = [f"r{i + 1}" for i in range(robots)]
    write_run(out, tuple(ids), iterations, respite)
    rng = random.Random(1)
    rounds = iterations // respite
    t0 = time.time() - seconds - 10.0
    per_round = seconds / rounds
    for i, rid in enumerate(ids):
        append(
            out / f"metrics_{rid}.csv",
            "".join(
                f"{rid},{k},{k * 0.01 + rng.random():.6f},{k * 0.02:.6f},{k // 400}\n"
                for k in range(1, iterations + 1)
            ),
        )
        append(
            out / f"shares_{rid}.csv",
            "".join(
                f"{rid},{k},{k * respite},{t0 + k * per_round + 0.5 - i * 0.01:.3f},d,{k},"
                f"fed_qlearning,1\n"
                for k in range(1, rounds + 1)
            ),
        )
    lines = []
    for k in range(1, rounds + 1):
        t = t0 + k * per_round
        for j, rid in enumerate(ids + ids[::-1]):
            phase = "forward" if j < robots else "backward"
            lines.append(
                {
                    "t": t + 0.01 * j,
                    "kind": "hop",
                    "agent": "fed_qlearning",
                    "robot": rid,
                    "phase": phase,
                    "round": k,
                }
            )
        append(out / "rounds_fed_qlearning.log", round_line(k, ids, t))
    for s in range(int(2 * seconds)):
        for rid in ids:
            lines.append(
                {
                    "t": t0 + 0.5 * s,
                    "kind": "pose",
                    "robot": rid,
                    "iteration": int(s * iterations / (2 * seconds)),
                    "x": rng.uniform(-0.4, 0.4),
                    "y": rng.uniform(-0.4, 0.4),
                    "yaw": rng.uniform(-3.1, 3.1),
                }
            )
    lines.sort(key=lambda e: e["t"])
    append(out / "events.jsonl", "".join(json.dumps(e) + "\n" for e in lines))
    append(
        out / "rounds_fed_qlearning.log",
        json.dumps({"event": "finished", "agent": "fed_qlearning", "round": rounds}) + "\n",
    )
    (out / "summary.md").write_text("# finished\n")
    # the files' times as the run left them: config first, the summary last
    for name, t in (
        ("config.json", t0 - 2.0),
        ("nodes.json", t0 - 1.0),
        ("summary.md", t0 + seconds + 1.0),
    ):
        os.utime(out / name, (t, t))
