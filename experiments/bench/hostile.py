"""Hostile peers against a node while an authenticated peer keeps moving an agent through it.

Two ``swipl`` processes (``hostile_node.pl`` beside this module) on loopback: the target node,
with the platform's default pre-authentication limits, and an authenticated peer whose agent
moves to the target and back, a short pause between hops (by default on a fresh connection
to the target each time, so every hop passes the target's acceptor and admission). First a
quiet phase, then one attack after another (:mod:`hostile_attacks`), each for the same time,
with a settling time after it:

``slowloris``  connections trickling one byte a second each (reconnecting when cut);
``flood``      connections opened and held (reopened when closed);
``frames``     concurrent senders of large hostile frames: ``a+a+...`` chains and ``[[[...]]]``
               nesting over the pre-auth limit, the same and ``f(f(...))`` just under it,
               and oversized binary frames.

Per phase: hops attempted (departures in the phase), succeeded, failed (the move raised) and
unfinished (neither by the end of the settling time); hop time median and p90 (call of the
move at the source to the start of the handler at the destination), the p90 against the quiet
p90; the target's RSS (``/proc/PID/status`` VmRSS) before the attack and after its settling
time, its CPU seconds and thread count; what became of the attack's connections. A phase
passes if no hop failed or went unfinished, at least one succeeded, the p90 is under
``P90_RATIO_MAX`` times the quiet p90 and RSS after is within ``RSS_DELTA_MAX_MB`` of before.
"""
from __future__ import annotations

import os
import shutil
import statistics
import subprocess
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from dfrl.experiments.bench.hostile_attacks import FRAME_KINDS, FrameSenders, Swarm, sources
from dfrl.experiments.bench.migrate import percentile

SCRIPT = Path(__file__).resolve().parent / "hostile_node.pl"
TOKEN = 4243
P90_RATIO_MAX = 10.0
RSS_DELTA_MAX_MB = 50.0
ATTACKS = ("slowloris", "flood", "frames")


@dataclass(frozen=True)
class HostileConfig:
    """What to run (the defaults are those of issue 9)."""

    slowloris: int = 70
    flood: int = 500
    frames: int = 32
    frame_size: int = 680_000
    duration_s: float = 20.0
    settle_s: float = 3.0
    sources: int = 4
    pause_ms: int = 50
    floats: int = 1000
    fresh: bool = True
    reconnect_s: float = 1.0
    frame_pause_s: float = 0.25
    frame_kinds: tuple[str, ...] = FRAME_KINDS

    def check(self) -> None:
        if min(self.slowloris, self.flood, self.frames, self.frame_size, self.sources) < 1:
            raise ValueError("slowloris, flood, frames, frame size and sources must be >= 1")
        if self.duration_s <= 0 or self.settle_s < 0 or self.pause_ms < 0 or self.floats < 0:
            raise ValueError("duration > 0, settle >= 0, pause >= 0 and floats >= 0 are required")
        sources(self.sources)
        unknown = set(self.frame_kinds) - set(FRAME_KINDS)
        if unknown or not self.frame_kinds:
            raise ValueError(f"unknown frame kinds {sorted(unknown)}; choose from {FRAME_KINDS}")


class _Node:
    """A ``hostile_node.pl`` process; its event lines are parsed by a reader thread."""

    def __init__(self, args: list[str], events: list[tuple], lock: threading.Lock) -> None:
        swipl = shutil.which("swipl")
        if swipl is None:
            raise FileNotFoundError("swipl is not installed (run scripts/setup.sh)")
        self.proc = subprocess.Popen([swipl, "-q", str(SCRIPT), *args], stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.events, self.lock = events, lock
        self.port: int | None = None
        self.ready = threading.Event()
        self.stderr: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()
        threading.Thread(target=self._read_err, daemon=True).start()
        if not self.ready.wait(20) or self.port is None:
            self.close()
            raise RuntimeError(f"node {args[0]} did not start: {''.join(self.stderr)[-2000:]}")

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            f = line.split()
            if not f:
                continue
            if f[0] == "PORT":
                self.port = int(f[1])
                self.ready.set()
            elif f[0] in ("DEPART", "HOP", "FAIL", "DONE"):
                with self.lock:
                    self.events.append((f[0], *f[1:]))
        self.ready.set()

    def _read_err(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            if len(self.stderr) < 200:
                self.stderr.append(line)

    def close(self) -> None:
        if self.proc.stdin:
            try:
                self.proc.stdin.close()
            except OSError:
                pass
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(10)


def _proc_status(pid: int) -> dict[str, float]:
    """RSS (MB) and threads of a process, and its user + system CPU seconds."""
    out: dict[str, float] = {}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            out["rss_mb"] = int(line.split()[1]) / 1024
        elif line.startswith("Threads:"):
            out["threads"] = int(line.split()[1])
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    out["cpu_s"] = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return out


class _Sampler(threading.Thread):
    """Peak RSS and threads of a process, sampled every 0.2 s until stopped."""

    def __init__(self, pid: int) -> None:
        super().__init__(daemon=True)
        self.pid, self.peak_rss, self.peak_threads = pid, 0.0, 0
        self.stopping = threading.Event()

    def run(self) -> None:
        while not self.stopping.wait(0.2):
            s = _proc_status(self.pid)
            self.peak_rss = max(self.peak_rss, s["rss_mb"])
            self.peak_threads = max(self.peak_threads, int(s["threads"]))

    def stop(self) -> None:
        self.stopping.set()
        self.join(5)


def hop_figures(events: list[tuple], t0: float, t1: float, until: float,
                target_port: int) -> dict[str, Any]:
    """Hops that departed in ``[t0, t1)``, their outcome known by ``until`` (event lines)."""
    departs = {(float(e[1]), e[2]) for e in events if e[0] == "DEPART" and t0 <= float(e[1]) < t1}
    arrived = {(float(e[1]), e[3]): (float(e[2]) - float(e[1])) * 1000.0 for e in events
               if e[0] == "HOP" and float(e[2]) <= until}
    failed = [e for e in events if e[0] == "FAIL" and (float(e[1]), e[3]) in departs]
    ms = [arrived[d] for d in departs if d in arrived]
    into = [arrived[d] for d in departs if d in arrived and int(d[1]) != target_port]
    fig: dict[str, Any] = {
        "attempted": len(departs), "succeeded": len(ms), "failed": len(failed),
        "unfinished": len(departs) - len(ms) - len(failed),
        "fail_examples": [" ".join(e[5:])[:300] for e in failed[:3]],
    }
    for key, xs in (("hop", ms), ("into_target", into)):
        fig[f"{key}_median_ms"] = round(statistics.median(xs), 3) if xs else None
        fig[f"{key}_p90_ms"] = round(percentile(xs, 0.9), 3) if xs else None
        fig[f"{key}_max_ms"] = round(max(xs), 3) if xs else None
    return fig


def _attacker(name: str, cfg: HostileConfig, port: int) -> Swarm | FrameSenders:
    srcs = sources(cfg.sources)
    limit = cfg.duration_s + 60
    if name == "slowloris":
        return Swarm(port, cfg.slowloris, srcs, trickle=True, reconnect_s=cfg.reconnect_s,
                     max_s=limit)
    if name == "flood":
        return Swarm(port, cfg.flood, srcs, trickle=False, reconnect_s=cfg.reconnect_s,
                     max_s=limit)
    return FrameSenders(port, cfg.frames, cfg.frame_size, srcs, cfg.frame_pause_s, max_s=limit,
                        kinds=cfg.frame_kinds)


def run(cfg: HostileConfig = HostileConfig(),
        attacks: tuple[str, ...] = ATTACKS) -> dict[str, Any]:
    """Run the quiet phase and each attack in turn; return the figures (see the module doc).

    Raises
    ------
    ValueError
        Bad configuration.
    FileNotFoundError
        swipl is not installed.
    RuntimeError
        A node did not start, an attacker failed or the target process died.
    """
    cfg.check()
    started = time.monotonic()
    events: list[tuple] = []
    lock = threading.Lock()
    budget = (len(attacks) + 1) * (cfg.duration_s + cfg.settle_s) + 30
    target = _Node(["target", str(TOKEN)], events, lock)
    peer = None
    try:
        assert target.port is not None
        pid = target.proc.pid
        peer = _Node(["peer", str(TOKEN), str(target.port), str(cfg.floats), str(cfg.pause_ms),
                      str(int(budget)), "true" if cfg.fresh else "false"], events, lock)
        time.sleep(1.0)                                   # warm-up hops, not counted
        phases = [_phase("quiet", None, cfg, pid, target.port, events, lock)]
        quiet_p90 = phases[0]["hops"]["hop_p90_ms"]
        for name in attacks:
            phases.append(_phase(name, _attacker(name, cfg, target.port), cfg, pid,
                                 target.port, events, lock, quiet_p90))
        if target.proc.poll() is not None:
            raise RuntimeError(f"the target node died: {''.join(target.stderr)[-2000:]}")
    finally:
        if peer is not None:
            peer.close()
        target.close()
    return {"benchmark": "hostile", "config": asdict(cfg),
            "targets": {"p90_ratio_max": P90_RATIO_MAX, "rss_delta_max_mb": RSS_DELTA_MAX_MB},
            "phases": phases, "pass": all(p["pass"] for p in phases),
            "wall_s": round(time.monotonic() - started, 1)}


def _phase(name: str, attacker: Swarm | FrameSenders | None, cfg: HostileConfig, pid: int,
           target_port: int, events: list[tuple], lock: threading.Lock,
           quiet_p90: float | None = None) -> dict[str, Any]:
    before = _proc_status(pid)
    sampler = _Sampler(pid)
    sampler.start()
    t0 = time.time()
    attack: dict[str, Any] | None = None
    try:
        if attacker is not None:
            attacker.start()
        time.sleep(cfg.duration_s)
    finally:
        t1 = time.time()
        if attacker is not None:
            attack = attacker.stop()
        time.sleep(cfg.settle_s)
        sampler.stop()
    after = _proc_status(pid)
    with lock:
        hops = hop_figures(list(events), t0, t1, time.time(), target_port)
    why: list[str] = []
    if hops["succeeded"] == 0:
        why.append("no hop succeeded")
    if hops["failed"] or hops["unfinished"]:
        why.append(f"{hops['failed']} hops failed, {hops['unfinished']} unfinished")
    ratio = None
    if quiet_p90 and hops["hop_p90_ms"] is not None:
        ratio = round(hops["hop_p90_ms"] / quiet_p90, 2)
        if ratio >= P90_RATIO_MAX:
            why.append(f"p90 {ratio}x the quiet p90 (limit {P90_RATIO_MAX:g}x)")
    delta = round(after["rss_mb"] - before["rss_mb"], 1)
    if delta > RSS_DELTA_MAX_MB:
        why.append(f"RSS grew by {delta} MB (limit {RSS_DELTA_MAX_MB:g})")
    return {
        "phase": name, "seconds": round(t1 - t0, 2), "hops": hops, "p90_ratio": ratio,
        "rss_mb": {"before": round(before["rss_mb"], 1), "after": round(after["rss_mb"], 1),
                   "peak": round(max(sampler.peak_rss, after["rss_mb"]), 1), "delta": delta},
        "threads": {"before": int(before["threads"]), "peak": sampler.peak_threads,
                    "after": int(after["threads"])},
        "target_cpu_s": round(after["cpu_s"] - before["cpu_s"], 2),
        "attack": attack, "pass": not why, "why": why,
    }
