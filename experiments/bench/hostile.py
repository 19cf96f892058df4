"""Hostile peers against a node while an authenticated peer keeps moving an agent through it.

Two ``swipl`` processes (``hostile_node.pl`` beside this module) on loopback: the target node,
with the platform's default limits, and an authenticated peer whose agent moves to the target
and back, a short pause between hops (by default on a fresh connection to the target each
time, so every hop passes the target's acceptor and admission). First a quiet phase, then one
attack after another, each for the same time, with a settling time after it. The attackers
run at the lowest CPU priority (``nice 19``: the Python ones in a process of their own,
:mod:`hostile_child`), so that a phase measures the node, not a CPU shared with the attack.
Attackers without a token (:mod:`hostile_attacks`):

``slowloris``  connections trickling one byte a second each (reconnecting when cut);
``flood``      connections opened and held (reopened when closed);
``frames``     concurrent senders of large hostile frames: ``a+a+...`` chains and ``[[[...]]]``
               nesting over the pre-auth limit, the same and ``f(f(...))`` just under it,
               and oversized binary frames.

Attackers with the target's token (:mod:`hostile_auth_attacks`): ``escapes`` (agents and
programs trying side doors of the sandbox), ``loop``, ``memory``, ``clone``, ``assert``,
``log``, ``post`` (waves of agents doing that on the target) and ``authframes`` (frames near
the target's ``max_frame_size`` and a flood of small requests). After each of those phases the
benchmark (as the target's operator) purges the agents they left there.

Per phase: hops attempted (departures in the phase), succeeded, failed (the move raised) and
unfinished (neither by the end of the settling time); hop time median and p90 (call of the
move at the source to the start of the handler at the destination), the p90 against the quiet
p90; the target's RSS (``/proc/PID/status`` VmRSS) before the attack and after its settling
time, its CPU seconds and thread count, its CPU use over ``CPU_WINDOW_S`` after settling; what
became of the attack's connections or agents; the agents the target hosts at the end. A phase
passes if no hop failed or went unfinished, at least one succeeded, the p90 is under
``P90_RATIO_MAX`` times the quiet p90, RSS after is within ``RSS_DELTA_MAX_MB`` of before,
threads after are within ``THREADS_DELTA_MAX`` of the quiet phase's, the settled CPU use is
within ``CPU_MARGIN`` (cores) of the quiet phase's, and no escape ran.
"""
from __future__ import annotations

import json
import os
import queue
import shutil
import subprocess
import tempfile
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from dfrl.experiments.bench.hostile_attacks import FRAME_KINDS, sources
from dfrl.experiments.bench.hostile_auth_attacks import (AGENT_ATTACKS, AUTH_ATTACKS,
                                                        AuthAttacker, escape_results)
from dfrl.experiments.bench.hostile_child import ChildAttacker
from dfrl.experiments.bench.hostile_measure import Sampler, hop_figures, proc_status

SCRIPT = Path(__file__).resolve().parent / "hostile_node.pl"
TOKEN = 4243
P90_RATIO_MAX = 10.0
RSS_DELTA_MAX_MB = 50.0
THREADS_DELTA_MAX = 16
CPU_MARGIN = 0.25
CPU_WINDOW_S = 1.0
ATTACKS = ("slowloris", "flood", "frames", *AUTH_ATTACKS)


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
    per_wave: int = 2
    wave_s: float = 5.0
    escape_wait_s: float = 3.0
    clone_depth: int = 12
    assert_facts: int = 1_000_000
    auth_big: int = 2
    auth_big_mb: float = 0.0
    auth_flood: int = 8
    trust_attacker: bool = False
    threads_wait_s: float = 35.0
    pool_idle_s: float = 0.0

    def check(self) -> None:
        if min(self.slowloris, self.flood, self.frames, self.frame_size, self.sources) < 1:
            raise ValueError("slowloris, flood, frames, frame size and sources must be >= 1")
        if self.duration_s <= 0 or self.settle_s < 0 or self.pause_ms < 0 or self.floats < 0:
            raise ValueError("duration > 0, settle >= 0, pause >= 0 and floats >= 0 are required")
        sources(self.sources)
        if min(self.per_wave, self.clone_depth, self.assert_facts) < 1 or self.wave_s <= 0:
            raise ValueError("per wave, clone depth and assert facts >= 1, wave_s > 0 required")
        if self.auth_big < 0 or self.auth_flood < 0 or self.auth_big_mb < 0:
            raise ValueError("authframes senders and size must be >= 0")
        unknown = set(self.frame_kinds) - set(FRAME_KINDS)
        if unknown or not self.frame_kinds:
            raise ValueError(f"unknown frame kinds {sorted(unknown)}; choose from {FRAME_KINDS}")


class _Node:
    """A ``hostile_node.pl`` process; its event lines are parsed by a reader thread."""

    def __init__(self, args: list[str], events: list[tuple], lock: threading.Lock,
                 env: dict[str, str] | None = None) -> None:
        swipl = shutil.which("swipl")
        if swipl is None:
            raise FileNotFoundError("swipl is not installed (run scripts/setup.sh)")
        self.proc = subprocess.Popen([swipl, "-q", str(SCRIPT), *args],
                                     env={**os.environ, **(env or {})}, stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.events, self.lock = events, lock
        self.replies: queue.Queue[dict[str, Any]] = queue.Queue()
        self.other_lines = 0
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
            elif f[0].startswith("{"):
                try:
                    self.replies.put(json.loads(line))
                except json.JSONDecodeError:
                    self.other_lines += 1
            else:
                self.other_lines += 1           # e.g. a log flood's lines
        self.ready.set()

    def command(self, name: str, timeout_s: float = 20.0) -> dict[str, Any]:
        """Send the target a command (``probe``, ``purge``); its JSON reply."""
        while not self.replies.empty():
            self.replies.get_nowait()
        assert self.proc.stdin is not None
        self.proc.stdin.write(f"{name}.\n")
        self.proc.stdin.flush()
        try:
            return self.replies.get(timeout=timeout_s)
        except queue.Empty:
            raise RuntimeError(f"the target did not answer {name} in {timeout_s:g} s") from None

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


Attacker = ChildAttacker | AuthAttacker


@dataclass
class _Bench:
    """What every phase needs: the target, the events, the quiet phase's figures."""

    cfg: HostileConfig
    target: _Node
    events: list[tuple]
    lock: threading.Lock
    marker_dir: Path
    quiet: dict[str, Any] | None = None


def _attacker(name: str, b: _Bench) -> Attacker:
    cfg, port = b.cfg, b.target.port
    assert port is not None
    limit = cfg.duration_s + 60
    if name in ("slowloris", "flood", "frames"):
        return ChildAttacker({
            "kind": name, "port": port, "max_s": limit, "sources": cfg.sources,
            "n": {"slowloris": cfg.slowloris, "flood": cfg.flood, "frames": cfg.frames}[name],
            "reconnect_s": cfg.reconnect_s, "frame_size": cfg.frame_size,
            "pause_s": cfg.frame_pause_s, "kinds": list(cfg.frame_kinds)})
    if name == "authframes":
        max_frame = int(b.target.command("probe")["max_frame_size"])
        big = max_frame - 65536 if cfg.auth_big_mb == 0 else int(cfg.auth_big_mb * 2**20)
        return ChildAttacker({"kind": name, "port": port, "max_s": limit, "token": TOKEN,
                              "big": cfg.auth_big, "big_size": max(64, big),
                              "flood": cfg.auth_flood})
    options: dict[str, Any] = {"duration_s": cfg.duration_s}
    if b.cfg.trust_attacker:
        options["tls"] = b.marker_dir / "pki" / "attacker"
    if name == "escapes":
        options |= {"marker_dir": b.marker_dir / "markers", "wait_s": cfg.escape_wait_s}
    else:
        options |= {"per_wave": cfg.per_wave, "wave_s": cfg.wave_s}
        if name == "clone":
            options["size"] = cfg.clone_depth
        elif name == "assert":
            options["size"] = cfg.assert_facts
    return AuthAttacker(name, TOKEN, port, options)


def _trust_args(tmp: Path) -> tuple[list[str], list[str]]:
    """The control run: a CA, certificates for the target, the peer and the attacker; the
    target trusts the attacker by name. The extra arguments of the target and of the peer."""
    from dfrl.experiments.certs import init_ca, make_node

    init_ca(tmp / "pki")
    dirs = {n: make_node(n, tmp / "pki").directory for n in ("target", "peer", "attacker")}
    return [str(dirs["target"]), "attacker"], [str(dirs["peer"])]


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
    unknown = set(attacks) - set(ATTACKS)
    if unknown:
        raise ValueError(f"unknown attacks {sorted(unknown)}; choose from {ATTACKS}")
    started = time.monotonic()
    events: list[tuple] = []
    lock = threading.Lock()
    budget = (len(attacks) + 1) * (cfg.duration_s + cfg.settle_s + CPU_WINDOW_S + 10
                                   + cfg.threads_wait_s) + 30
    with tempfile.TemporaryDirectory(prefix="dfrl-hostile-") as tmp_name:
        tmp = Path(tmp_name)
        (tmp / "markers").mkdir()
        target_extra, peer_extra = _trust_args(tmp) if cfg.trust_attacker else ([], [])
        env = {"DFRL_HOSTILE_POOL_IDLE": f"{cfg.pool_idle_s:g}"} if cfg.pool_idle_s > 0 else {}
        target = _Node(["target", str(TOKEN), *target_extra], events, lock, env)
        peer = None
        try:
            assert target.port is not None
            peer = _Node(["peer", str(TOKEN), str(target.port), str(cfg.floats),
                          str(cfg.pause_ms), str(int(budget)), "true" if cfg.fresh else "false",
                          *peer_extra], events, lock)
            time.sleep(1.0)                                   # warm-up hops, not counted
            b = _Bench(cfg, target, events, lock, tmp)
            phases = [_phase("quiet", b)]
            b.quiet = phases[0]
            for name in attacks:
                phases.append(_phase(name, b))
                if target.proc.poll() is not None:
                    raise RuntimeError(f"the target node died in phase {name}: "
                                       f"{''.join(target.stderr)[-2000:]}")
        finally:
            if peer is not None:
                peer.close()
            target.close()
    return {"benchmark": "hostile", "config": asdict(cfg),
            "targets": {"p90_ratio_max": P90_RATIO_MAX, "rss_delta_max_mb": RSS_DELTA_MAX_MB,
                        "threads_delta_max": THREADS_DELTA_MAX, "cpu_margin_cores": CPU_MARGIN},
            "phases": phases, "pass": all(p["pass"] for p in phases),
            "wall_s": round(time.monotonic() - started, 1)}


def _phase(name: str, b: _Bench) -> dict[str, Any]:
    cfg, pid = b.cfg, b.target.proc.pid
    attacker = None if name == "quiet" else _attacker(name, b)
    dq_before = b.target.command("probe")["double_quotes"]
    before = proc_status(pid)
    lines_before = b.target.other_lines
    sampler = Sampler(pid)
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
    after = proc_status(pid)
    time.sleep(CPU_WINDOW_S)
    cpu_settled = (proc_status(pid)["cpu_s"] - after["cpu_s"]) / CPU_WINDOW_S
    threads, waited = _threads_back(pid, b, time.monotonic() + cfg.threads_wait_s)
    probe = b.target.command("probe")
    with b.lock:
        hops = hop_figures(list(b.events), t0, t1, time.time(), b.target.port or 0)
    escapes = None
    if name == "escapes" and attack is not None:
        escapes = escape_results(attack.pop("escapes"), TOKEN, dq_before, probe["double_quotes"])
    elif attack is not None and "escapes" in attack:
        attack.pop("escapes")
    purged = b.target.command("purge")["agents"] if name in AUTH_ATTACKS else 0
    cpu_rate = (after["cpu_s"] - before["cpu_s"]) / max(1e-9, t1 - t0 + cfg.settle_s)
    why = _misses(hops, b.quiet, before, after | {"threads": threads}, cpu_settled, escapes)
    return {
        "phase": name, "seconds": round(t1 - t0, 2), "hops": hops,
        "p90_ratio": _ratio(hops, b.quiet),
        "rss_mb": {"before": round(before["rss_mb"], 1), "after": round(after["rss_mb"], 1),
                   "peak": round(max(sampler.peak_rss, after["rss_mb"]), 1),
                   "delta": round(after["rss_mb"] - before["rss_mb"], 1)},
        "threads": {"before": int(before["threads"]), "peak": sampler.peak_threads,
                    "after": int(after["threads"]), "back": threads, "waited_s": waited},
        "target_cpu_s": round(after["cpu_s"] - before["cpu_s"], 2),
        "cpu_cores": {"phase": round(cpu_rate, 3), "settled": round(cpu_settled, 3)},
        "agents_at_end": probe["agents"], "agents_purged": purged,
        "target_other_lines": b.target.other_lines - lines_before,
        "attack": attack, "escapes": escapes, "pass": not why, "why": why,
    }


def _threads_back(pid: int, b: _Bench, until: float) -> tuple[int, float]:
    """Threads of the target once back within the bound of the quiet phase's (idle pool
    workers exit after the pool's idle time), or at ``until``; and the seconds waited."""
    t0 = time.monotonic()
    while True:
        n = int(proc_status(pid)["threads"])
        if b.quiet is None or n <= b.quiet["threads"]["after"] + THREADS_DELTA_MAX \
                or time.monotonic() >= until:
            return n, round(time.monotonic() - t0, 1)
        time.sleep(0.5)


def _ratio(hops: dict[str, Any], quiet: dict[str, Any] | None) -> float | None:
    q = quiet["hops"]["hop_p90_ms"] if quiet else None
    if not q or hops["hop_p90_ms"] is None:
        return None
    return round(hops["hop_p90_ms"] / q, 2)


def _misses(hops: dict[str, Any], quiet: dict[str, Any] | None, before: dict[str, float],
            after: dict[str, float], cpu_settled: float,
            escapes: dict[str, Any] | None) -> list[str]:
    """The targets a phase missed (see the module doc); none for a pass."""
    why: list[str] = []
    if hops["succeeded"] == 0:
        why.append("no hop succeeded")
    if hops["failed"] or hops["unfinished"]:
        why.append(f"{hops['failed']} hops failed, {hops['unfinished']} unfinished")
    ratio = _ratio(hops, quiet)
    if ratio is not None and ratio >= P90_RATIO_MAX:
        why.append(f"p90 {ratio}x the quiet p90 (limit {P90_RATIO_MAX:g}x)")
    delta = round(after["rss_mb"] - before["rss_mb"], 1)
    if delta > RSS_DELTA_MAX_MB:
        why.append(f"RSS grew by {delta} MB (limit {RSS_DELTA_MAX_MB:g})")
    if quiet is not None:
        if after["threads"] > quiet["threads"]["after"] + THREADS_DELTA_MAX:
            why.append(f"{int(after['threads'])} threads after settling and waiting, quiet "
                       f"{quiet['threads']['after']} (limit +{THREADS_DELTA_MAX})")
        if cpu_settled > quiet["cpu_cores"]["phase"] + CPU_MARGIN:
            why.append(f"CPU {cpu_settled:.2f} cores after settling, quiet "
                       f"{quiet['cpu_cores']['phase']:.2f} (limit +{CPU_MARGIN:g})")
    if escapes is not None and escapes["ran"]:
        why.append(f"{escapes['ran']} escapes ran: {', '.join(escapes['ran_names'])}")
    return why
