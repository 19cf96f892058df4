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
unfinished (neither by the end of the phase's measurements); hop time median and p90 (call of
the move at the source to the start of the handler at the destination), the p90 against the
quiet p90; the target's RSS (``/proc/PID/status`` VmRSS) before the attack, after its
settling time and once its threads have settled (the attack's workers gone idle: the RSS the
criterion reads), its CPU seconds, its CPU use over ``CPU_WINDOW_S`` after settling; its threads
(``/proc/PID/status`` Threads) sampled every 0.2 s from the attack's start to the end of the
phase (the peak), and its worker pools (``worker_pool:pool_statistics/2``, read through the
target's ``probe.``); what became of the attack's connections or agents; the agents the
target hosts at the end. When a phase passes: :mod:`hostile_verdict`.
"""

from __future__ import annotations

import statistics
import tempfile
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from dfrl.experiments.tools.bench import hostile_verdict as verdict
from dfrl.experiments.tools.bench.hostile_attacks import FRAME_KINDS, sources
from dfrl.experiments.tools.bench.hostile_auth_attacks import (
    AUTH_ATTACKS,
    AuthAttacker,
    escape_results,
)
from dfrl.experiments.tools.bench.hostile_child import ChildAttacker
from dfrl.experiments.tools.bench.hostile_measure import Sampler, hop_figures, proc_status
from dfrl.experiments.tools.bench.hostile_nodes import HostileNode
from dfrl.experiments.tools.certs import init_ca, make_node

TOKEN = 4243
IDLE_MARGIN_S = 1.0  # after the pools' idle time, before threads are counted
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
    threads_wait_s: float = 10.0
    pool_idle_s: float = 5.0

    def check(self) -> None:
        if min(self.slowloris, self.flood, self.frames, self.frame_size, self.sources) < 1:
            raise ValueError("slowloris, flood, frames, frame size and sources must be >= 1")
        if self.duration_s <= 0 or self.settle_s < 0 or self.pause_ms < 0 or self.floats < 0:
            raise ValueError("duration > 0, settle >= 0, pause >= 0 and floats >= 0 are required")
        sources(self.sources)
        if min(self.per_wave, self.clone_depth, self.assert_facts) < 1 or self.wave_s <= 0:
            raise ValueError("per wave, clone depth and assert facts >= 1, wave_s > 0 required")
        if self.threads_wait_s < 0 or self.pool_idle_s < 0:
            raise ValueError("threads wait and pool idle must be >= 0")
        if self.auth_big < 0 or self.auth_flood < 0 or self.auth_big_mb < 0:
            raise ValueError("authframes senders and size must be >= 0")
        unknown = set(self.frame_kinds) - set(FRAME_KINDS)
        if unknown or not self.frame_kinds:
            raise ValueError(f"unknown frame kinds {sorted(unknown)}; choose from {FRAME_KINDS}")


Attacker = ChildAttacker | AuthAttacker


@dataclass
class _Bench:
    """What every phase needs: the target, the events, the quiet phase's figures."""

    cfg: HostileConfig
    target: HostileNode
    events: list[tuple]
    lock: threading.Lock
    marker_dir: Path
    peer: HostileNode
    quiet: dict[str, Any] | None = None
    nonpool: int = 0  # threads of the quiet target outside its pools
    limits: dict[str, int] = field(default_factory=dict)
    pool_idle_s: float = 30.0  # the target's dfrl_pool_idle


def _outside_pools(b: _Bench, samples: int = 3) -> int:
    """Threads of the target that are not pool workers (the median of ``samples`` counts, each
    less the pools' sizes that the target reports right after it)."""
    counts = []
    for _ in range(samples):
        n = int(proc_status(b.target.proc.pid)["threads"])
        pools = b.target.command("probe")["pools"]
        counts.append(n - sum(v["size"] for v in pools.values()))
        time.sleep(0.2)
    return int(statistics.median(counts))


def _attacker(name: str, b: _Bench) -> Attacker:
    cfg, port = b.cfg, b.target.port
    assert port is not None
    limit = cfg.duration_s + 60
    if name in ("slowloris", "flood", "frames"):
        return ChildAttacker(
            {
                "kind": name,
                "port": port,
                "max_s": limit,
                "sources": cfg.sources,
                "n": {"slowloris": cfg.slowloris, "flood": cfg.flood, "frames": cfg.frames}[name],
                "reconnect_s": cfg.reconnect_s,
                "frame_size": cfg.frame_size,
                "pause_s": cfg.frame_pause_s,
                "kinds": list(cfg.frame_kinds),
            }
        )
    if name == "authframes":
        max_frame = int(b.target.command("probe")["max_frame_size"])
        big = max_frame - 65536 if cfg.auth_big_mb == 0 else int(cfg.auth_big_mb * 2**20)
        return ChildAttacker(
            {
                "kind": name,
                "port": port,
                "max_s": limit,
                "token": TOKEN,
                "big": cfg.auth_big,
                "big_size": max(64, big),
                "flood": cfg.auth_flood,
            }
        )
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
    init_ca(tmp / "pki")
    dirs = {n: make_node(n, tmp / "pki").directory for n in ("target", "peer", "attacker")}
    return [str(dirs["target"]), "attacker"], [str(dirs["peer"])]


def run(cfg: HostileConfig = HostileConfig(), attacks: tuple[str, ...] = ATTACKS) -> dict[str, Any]:
    """Run the quiet phase and each attack in turn; return the figures (see the module doc).

    Raises
    ------
    ValueError
        Bad configuration.
    ExperimentError
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
    idle = cfg.pool_idle_s or 30.0
    budget = (len(attacks) + 1) * (
        cfg.duration_s
        + 10
        + max(
            cfg.settle_s + CPU_WINDOW_S,
            idle + IDLE_MARGIN_S + cfg.threads_wait_s,
            verdict.ACCEPT_MAX_S + 1,
        )
    ) + 30
    with tempfile.TemporaryDirectory(prefix="dfrl-hostile-") as tmp_name:
        tmp = Path(tmp_name)
        (tmp / "markers").mkdir()
        target_extra, peer_extra = _trust_args(tmp) if cfg.trust_attacker else ([], [])
        env = {"DFRL_HOSTILE_POOL_IDLE": f"{cfg.pool_idle_s:g}"} if cfg.pool_idle_s > 0 else {}
        target = HostileNode(["target", str(TOKEN), *target_extra], events, lock, env)
        peer = None
        try:
            assert target.port is not None
            peer = HostileNode(
                [
                    "peer",
                    str(TOKEN),
                    str(target.port),
                    str(cfg.floats),
                    str(cfg.pause_ms),
                    str(int(budget)),
                    "true" if cfg.fresh else "false",
                    *peer_extra,
                ],
                events,
                lock,
            )
            time.sleep(1.0)  # warm-up hops, not counted
            b = _Bench(cfg, target, events, lock, tmp, peer)
            probe = target.command("probe")
            b.limits = {
                k: int(probe[k])
                for k in ("max_connections", "max_agents", "connection_workers_max")
            }
            b.pool_idle_s = float(probe["pool_idle_s"])
            b.nonpool = _outside_pools(b)
            phases = [_phase("quiet", b)]
            b.quiet = phases[0]
            for name in attacks:
                phases.append(_phase(name, b))
                if target.proc.poll() is not None:
                    raise RuntimeError(
                        f"the target node died in phase {name}: {''.join(target.stderr)[-2000:]}"
                    )
        finally:
            if peer is not None:
                peer.close()
            target.close()
    pool_idle, limits = b.pool_idle_s, b.limits
    return {
        "benchmark": "hostile",
        "config": asdict(cfg),
        "targets": {
            "p90_ratio_max": verdict.P90_RATIO_MAX,
            "rss_delta_max_mb": verdict.RSS_DELTA_MAX_MB,
            "accept_max_s": verdict.ACCEPT_MAX_S,
            "keep_warm": verdict.KEEP_WARM,
            "settled_slack": verdict.SETTLED_SLACK,
            "peak_slack": verdict.PEAK_SLACK,
            "cpu_margin_cores": verdict.CPU_MARGIN,
            "target_pool_idle_s": pool_idle,
            "target_limits": limits,
            "threads": "peak < thread_ceiling; after the pools' idle time, "
            "threads <= settled_bound (see the module doc)",
        },
        "phases": phases,
        "pass": all(p["pass"] for p in phases),
        "wall_s": round(time.monotonic() - started, 1),
    }


def _phase(name: str, b: _Bench) -> dict[str, Any]:
    cfg, pid = b.cfg, b.target.proc.pid
    attacker = None if name == "quiet" else _attacker(name, b)
    dq_before = b.target.command("probe")["double_quotes"]
    before = proc_status(pid)
    lines_before = b.target.other_lines
    peer_lines_before = len(b.peer.stderr)
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
        try:
            if attacker is not None:
                attack = attacker.stop()
        finally:
            t_end = time.time()  # the attacker stopped and is gone
            time.sleep(cfg.settle_s)
    after = proc_status(pid)
    time.sleep(CPU_WINDOW_S)
    cpu_settled = (proc_status(pid)["cpu_s"] - after["cpu_s"]) / CPU_WINDOW_S
    threads = _threads_settled(pid, b, t_end)
    settled_rss = proc_status(pid)["rss_mb"]  # RSS once the attack's workers have gone idle
    accept_s = _accepted_after(b, t_end)
    sampler.stop()
    probe = b.target.command("probe")
    with b.lock:
        hops = hop_figures(list(b.events), t0, t1, time.time(), b.target.port or 0)
    escapes = None
    if name == "escapes" and attack is not None:
        escapes = escape_results(attack.pop("escapes"), TOKEN, dq_before, probe["double_quotes"])
    elif attack is not None and "escapes" in attack:
        attack.pop("escapes")
    purged = b.target.command("purge")["agents"] if name in AUTH_ATTACKS else 0
    lost = [
        line.strip()[:300]
        for line in b.peer.stderr[peer_lines_before:]
        if "hostile_bencher" in line
    ]
    relaunched = bool(lost) and b.peer.command("relaunch")["launched"]
    cpu_rate = (after["cpu_s"] - before["cpu_s"]) / max(1e-9, t_end - t0 + cfg.settle_s)
    threads |= {
        "before": int(before["threads"]),
        "after_settle": int(after["threads"]),
        "peak": sampler.peak_threads,
        "peak_ceiling": verdict.thread_ceiling(b.nonpool, b.limits),
        "quiet_outside_pools": b.nonpool,
    }
    phase = {
        "phase": name,
        "seconds": round(t1 - t0, 2),
        "hops": hops,
        "p90_ratio": verdict.p90_ratio(hops, b.quiet),
        "accepted_after_s": accept_s,
        "rss_mb": {
            "before": round(before["rss_mb"], 1),
            "after": round(settled_rss, 1),
            "after_settle_s": round(after["rss_mb"], 1),
            "peak": round(max(sampler.peak_rss, after["rss_mb"], settled_rss), 1),
            "delta": round(settled_rss - before["rss_mb"], 1),
        },
        "threads": threads,
        "target_cpu_s": round(after["cpu_s"] - before["cpu_s"], 2),
        "cpu_cores": {"phase": round(cpu_rate, 3), "settled": round(cpu_settled, 3)},
        "agents_at_end": probe["agents"],
        "agents_purged": purged,
        "target_other_lines": b.target.other_lines - lines_before,
        "attack": attack,
        "escapes": escapes,
        "peer_agent_stopped": lost,
        "peer_agent_relaunched": relaunched,
    }
    why = verdict.misses(phase, b.quiet)
    return phase | {"pass": not why, "why": why}


def _threads_settled(pid: int, b: _Bench, t_end: float) -> dict[str, Any]:
    """Threads of the target once the pools' idle time has passed since ``t_end`` (plus
    ``IDLE_MARGIN_S``): the first count at or under :func:`settled_bound` within
    ``threads_wait_s`` more, else the last; the seconds since ``t_end``; the pools then."""
    start = t_end + b.pool_idle_s + IDLE_MARGIN_S
    until = start + b.cfg.threads_wait_s
    time.sleep(max(0.0, start - time.time()))
    bound = verdict.settled_bound(b.nonpool, b.limits) if b.limits else None
    while True:
        n = int(proc_status(pid)["threads"])
        if bound is None or n <= bound or time.time() >= until:
            break
        time.sleep(0.5)
    pools = b.target.command("probe")["pools"]
    return {
        "settled": n,
        "settled_bound": bound,
        "settled_after_s": round(time.time() - t_end, 1),
        "pools_settled": pools,
    }


def _accepted_after(b: _Bench, t_end: float) -> float | None:
    """Seconds from ``t_end`` to the first start of the peer's agent at the target (an ordinary
    agent accepted); waits up to ``ACCEPT_MAX_S`` + 1 s after ``t_end``; None if none."""
    port = str(b.target.port)
    while True:
        with b.lock:
            arrivals = [
                float(e[2])
                for e in b.events
                if e[0] == "HOP" and e[4] == port and float(e[2]) >= t_end
            ]
        if arrivals:
            return round(min(arrivals) - t_end, 2)
        if time.time() >= t_end + verdict.ACCEPT_MAX_S + 1:
            return None
        time.sleep(0.2)
