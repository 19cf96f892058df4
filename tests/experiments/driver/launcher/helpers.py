"""Helpers of the launcher tests: configs, reading a results folder, a run in a thread."""

from __future__ import annotations

import csv
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from dfrl.experiments.driver.config import ExperimentConfig, RobotSpec
from dfrl.experiments.driver.launcher import Launcher, run
from dfrl.experiments.driver.results.agent_log import read_rounds_log
from dfrl.experiments.tokens import env_with_tokens


def rounds_csv(out: Path) -> list[dict[str, str]]:
    """The rows of ``OUT/rounds.csv`` as written (strings)."""
    with open(out / "rounds.csv", newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def diagnose(*outs: Path) -> str:
    """Rounds and node warnings of runs, for a failure message."""
    text = []
    for out in outs:
        text.append(f"--- {out}")
        text += [
            f"{r['round']} {r['method']} [{r['visited']}] {r['all_equal']}" for r in rounds_csv(out)
        ]
        for err in sorted((out / "logs").glob("*")):
            lines = [
                ln
                for ln in err.read_text(errors="replace").splitlines()
                if ln and not ln.startswith("pybullet build time")
            ]
            text += [f"{err.name}: {ln}" for ln in lines[:10]]
    return "\n".join(text)


def small_config(n: int = 2, **kw: Any) -> ExperimentConfig:
    """``n`` robots in r1, r4, r2, r3, r5; 200 iterations, respite 50, sync."""
    arenas = ["r1", "r4", "r2", "r3", "r5"]
    base: dict[str, Any] = dict(
        name="t",
        robots=tuple(RobotSpec(f"r{i + 1}", arenas[i]) for i in range(n)),
        iterations=200,
        respite=50,
        seed=1,
        mode="sync",
        timeout_s=120,
    )
    base.update(kw)
    return ExperimentConfig(**base)


def run_in_thread(
    cfg: ExperimentConfig, out: Path, **run_options: Any
) -> tuple[threading.Thread, dict[str, Any]]:
    """Start ``run(cfg, out, **run_options)`` in a thread (``tls=DIR``, say); its result or
    exception lands in the dict."""
    return call_in_thread(lambda: run(cfg, out, progress=None, **run_options))


def launcher_in_thread(
    cfg: ExperimentConfig, out: Path
) -> tuple[Launcher, threading.Thread, dict[str, Any]]:
    """A :class:`Launcher` of ``cfg`` running in a thread (its robots can be reached while it
    runs); its result or exception lands in the dict."""
    launcher = Launcher(cfg, out, progress=None)
    return (launcher, *call_in_thread(launcher.run))


def call_in_thread(call: Any) -> tuple[threading.Thread, dict[str, Any]]:
    """``call()`` in a daemon thread; its result (``res``) or exception (``exc``) in the dict."""
    box: dict[str, Any] = {}

    def target() -> None:
        try:
            box["res"] = call()
        except BaseException as exc:  # noqa: BLE001 - the caller asserts on it
            box["exc"] = exc

    t = threading.Thread(target=target, daemon=True)
    t.start()
    return t, box


def wait_rounds(out: Path, agent: str, n: int, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if len(read_rounds_log(out / f"rounds_{agent}.log", agent).rounds) >= n:
            return
        time.sleep(0.05)
    raise AssertionError(f"fewer than {n} rounds after {timeout} s")


def stop_agents(out: Path, tls: Path | None = None) -> None:
    """Tell every agent of the running experiment in ``out`` to stop at its next round start
    (the ``stop`` control command; a sync run then ends within seconds). Tests that act on a
    running experiment run a long one and end it so once they acted, instead of betting that
    their commands finish before a short run does (they did not on a loaded machine)."""
    from dfrl.experiments.driver.launcher import open_console, send_control
    from dfrl.experiments.driver.launcher.remote import driver_tls, nodes_of, tokens_of

    info = nodes_of(out)
    with open_console(tokens_of(out), tls=driver_tls(out, info, tls)) as console:
        for a in info["agents"]:
            first = a["itinerary"][0]
            send_control(console, (first["host"], int(first["port"])), a["name"], {"stop": True})


def robot_service(workdir: Path, *flags: str, token: int = 1111) -> tuple[subprocess.Popen, int]:
    """A ``dfrl robot`` service on a free loopback port with ``token`` and ``flags``, up
    (its "listening on" line read); the caller terminates it."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    workdir.mkdir()
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
            str(workdir),
            *flags,
        ],
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env_with_tokens([token]),
    )
    assert svc.stdout is not None and svc.stderr is not None
    line = svc.stdout.readline()
    assert "listening on" in line, line + svc.stderr.read()
    return svc, port


def dfrl_inject(out: Path, program: Path, method: str) -> subprocess.CompletedProcess[str]:
    """``dfrl inject OUT --program PROGRAM --method METHOD`` (waiting up to 60 s)."""
    return subprocess.run(
        [
            sys.executable,
            "-m",
            "dfrl",
            "inject",
            str(out),
            "--program",
            str(program),
            "--method",
            method,
            "--wait",
            "60",
        ],
        capture_output=True,
        text=True,
        timeout=120,
    )
