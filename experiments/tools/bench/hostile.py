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
target hosts at the end. A phase passes if

* no hop failed or went unfinished and at least one succeeded;
* the p90 is under ``P90_RATIO_MAX`` times the quiet p90;
* RSS once the threads have settled is within ``RSS_DELTA_MAX_MB`` of before (read at the
  settling time instead, a flood's idle connection workers, still alive then, once counted
  50.6 MB);
* an ordinary agent is accepted (the peer's agent starts its handler at the target) within
  ``ACCEPT_MAX_S`` of the attack's end (the attacker stopped and gone);
* the peak of threads stays under the ceiling that the node's limits allow
  (:func:`thread_ceiling`: the threads of the quiet target outside its pools, plus the most
  workers of the connection pool (twice ``max_connections``), ``max_agents`` for the agents
  pool, ``max_agents`` again for the messages pool, 2 for the bound notices pool, plus
  ``PEAK_SLACK``). The messages pool is the one the node does not bound by a limit of its own
  (only by the pool's maximum, 1000): the ceiling assumes one running message per agent, so a
  phase that needs more fails and shows it;
* once the pools' idle time has passed after the attack's end (the target runs with
  ``dfrl_pool_idle`` = ``pool_idle_s``, 5 s by default, instead of the node's 30 s, to keep
  the benchmark short), threads come down, within ``threads_wait_s``, to at most the quiet
  target's threads outside its pools plus the workers its pools keep warm (``KEEP_WARM`` each,
  at most the pool's maximum) plus ``SETTLED_SLACK`` (the peer's hop in flight):
  :func:`settled_bound`;
* the target did not stop the peer's agent (its home, the peer, was not told so; if it was,
  the benchmark starts a new one after the phase, so that the next phases measure again);
* the settled CPU use is within ``CPU_MARGIN`` (cores) of the quiet phase's;
* no escape ran.
"""
from __future__ import annotations

import json
import os
import queue
import shutil
import statistics
import subprocess
import tempfile
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from dfrl.experiments.tools.bench.hostile_attacks import FRAME_KINDS, sources
from dfrl.experiments.tools.bench.hostile_auth_attacks import (AGENT_ATTACKS, AUTH_ATTACKS,
                                                        AuthAttacker, escape_results)
from dfrl.experiments.tools.bench.hostile_child import ChildAttacker
from dfrl.experiments.tools.bench.hostile_measure import Sampler, hop_figures, proc_status

SCRIPT = Path(__file__).resolve().parent / "hostile_node.pl"
TOKEN = 4243
P90_RATIO_MAX = 10.0
RSS_DELTA_MAX_MB = 50.0
KEEP_WARM = 8            # worker_pool.pl's keep(8): the node's pools pass no keep option
SETTLED_SLACK = 4        # the peer's hop in flight: a connection worker, its handler, a transient
PEAK_SLACK = 8           # threads that exit while their replacement starts, between two samples
ACCEPT_MAX_S = 20.0      # issue 16: an ordinary agent is accepted within 20 s
IDLE_MARGIN_S = 1.0      # after the pools' idle time, before threads are counted
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
        """Send the node a command (the target: ``probe``, ``purge``; the peer: ``relaunch``);
        its JSON reply."""
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
    peer: _Node
    quiet: dict[str, Any] | None = None
    nonpool: int = 0                     # threads of the quiet target outside its pools
    limits: dict[str, int] = field(default_factory=dict)
    pool_idle_s: float = 30.0            # the target's dfrl_pool_idle


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
    from dfrl.experiments.tools.certs import init_ca, make_node

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
    idle = cfg.pool_idle_s or 30.0
    budget = (len(attacks) + 1) * (cfg.duration_s + 10 + max(
        cfg.settle_s + CPU_WINDOW_S, idle + IDLE_MARGIN_S + cfg.threads_wait_s,
        ACCEPT_MAX_S + 1)) + 30
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
            b = _Bench(cfg, target, events, lock, tmp, peer)
            probe = target.command("probe")
            b.limits = {k: int(probe[k]) for k in
                        ("max_connections", "max_agents", "connection_workers_max")}
            b.pool_idle_s = float(probe["pool_idle_s"])
            b.nonpool = _outside_pools(b)
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
    pool_idle, limits = b.pool_idle_s, b.limits
    return {"benchmark": "hostile", "config": asdict(cfg),
            "targets": {"p90_ratio_max": P90_RATIO_MAX, "rss_delta_max_mb": RSS_DELTA_MAX_MB,
                        "accept_max_s": ACCEPT_MAX_S, "keep_warm": KEEP_WARM,
                        "settled_slack": SETTLED_SLACK, "peak_slack": PEAK_SLACK,
                        "cpu_margin_cores": CPU_MARGIN,
                        "target_pool_idle_s": pool_idle, "target_limits": limits,
                        "threads": "peak < thread_ceiling; after the pools' idle time, "
                                   "threads <= settled_bound (see the module doc)"},
            "phases": phases, "pass": all(p["pass"] for p in phases),
            "wall_s": round(time.monotonic() - started, 1)}


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
            t_end = time.time()                 # the attacker stopped and is gone
            time.sleep(cfg.settle_s)
    after = proc_status(pid)
    time.sleep(CPU_WINDOW_S)
    cpu_settled = (proc_status(pid)["cpu_s"] - after["cpu_s"]) / CPU_WINDOW_S
    threads = _threads_settled(pid, b, t_end)
    settled_rss = proc_status(pid)["rss_mb"]   # RSS once the attack's workers have gone idle
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
    lost = [line.strip()[:300] for line in b.peer.stderr[peer_lines_before:]
            if "hostile_bencher" in line]
    relaunched = bool(lost) and b.peer.command("relaunch")["launched"]
    cpu_rate = (after["cpu_s"] - before["cpu_s"]) / max(1e-9, t_end - t0 + cfg.settle_s)
    threads |= {"before": int(before["threads"]), "after_settle": int(after["threads"]),
                "peak": sampler.peak_threads,
                "peak_ceiling": thread_ceiling(b.nonpool, b.limits),
                "quiet_outside_pools": b.nonpool}
    phase = {
        "phase": name, "seconds": round(t1 - t0, 2), "hops": hops,
        "p90_ratio": _ratio(hops, b.quiet), "accepted_after_s": accept_s,
        "rss_mb": {"before": round(before["rss_mb"], 1), "after": round(settled_rss, 1),
                   "after_settle_s": round(after["rss_mb"], 1),
                   "peak": round(max(sampler.peak_rss, after["rss_mb"], settled_rss), 1),
                   "delta": round(settled_rss - before["rss_mb"], 1)},
        "threads": threads,
        "target_cpu_s": round(after["cpu_s"] - before["cpu_s"], 2),
        "cpu_cores": {"phase": round(cpu_rate, 3), "settled": round(cpu_settled, 3)},
        "agents_at_end": probe["agents"], "agents_purged": purged,
        "target_other_lines": b.target.other_lines - lines_before,
        "attack": attack, "escapes": escapes,
        "peer_agent_stopped": lost, "peer_agent_relaunched": relaunched,
    }
    why = _misses(phase, b.quiet)
    return phase | {"pass": not why, "why": why}


def thread_ceiling(nonpool: int, limits: dict[str, int]) -> int:
    """The most threads the node's limits allow (see the module doc): ``nonpool`` threads
    outside the pools, every pool at the most workers its limits let it need, ``PEAK_SLACK``."""
    return (nonpool + limits["connection_workers_max"] + 2 * limits["max_agents"] + 2
            + PEAK_SLACK)


def settled_bound(nonpool: int, limits: dict[str, int]) -> int:
    """The most threads of a settled node (see the module doc): ``nonpool`` threads outside the
    pools, ``KEEP_WARM`` idle workers in each pool (at most its maximum), ``SETTLED_SLACK``."""
    pool_max = {"connections": limits["connection_workers_max"],
                "agents": limits["max_agents"], "messages": limits["max_agents"],
                "dfrl_bound_notices": 2}
    return nonpool + sum(min(KEEP_WARM, m) for m in pool_max.values()) + SETTLED_SLACK


def _threads_settled(pid: int, b: _Bench, t_end: float) -> dict[str, Any]:
    """Threads of the target once the pools' idle time has passed since ``t_end`` (plus
    ``IDLE_MARGIN_S``): the first count at or under :func:`settled_bound` within
    ``threads_wait_s`` more, else the last; the seconds since ``t_end``; the pools then."""
    start = t_end + b.pool_idle_s + IDLE_MARGIN_S
    until = start + b.cfg.threads_wait_s
    time.sleep(max(0.0, start - time.time()))
    bound = settled_bound(b.nonpool, b.limits) if b.limits else None
    while True:
        n = int(proc_status(pid)["threads"])
        if bound is None or n <= bound or time.time() >= until:
            break
        time.sleep(0.5)
    pools = b.target.command("probe")["pools"]
    return {"settled": n, "settled_bound": bound, "settled_after_s": round(time.time() - t_end, 1),
            "pools_settled": pools}


def _accepted_after(b: _Bench, t_end: float) -> float | None:
    """Seconds from ``t_end`` to the first start of the peer's agent at the target (an ordinary
    agent accepted); waits up to ``ACCEPT_MAX_S`` + 1 s after ``t_end``; None if none."""
    port = str(b.target.port)
    while True:
        with b.lock:
            arrivals = [float(e[2]) for e in b.events
                        if e[0] == "HOP" and e[4] == port and float(e[2]) >= t_end]
        if arrivals:
            return round(min(arrivals) - t_end, 2)
        if time.time() >= t_end + ACCEPT_MAX_S + 1:
            return None
        time.sleep(0.2)


def _ratio(hops: dict[str, Any], quiet: dict[str, Any] | None) -> float | None:
    q = quiet["hops"]["hop_p90_ms"] if quiet else None
    if not q or hops["hop_p90_ms"] is None:
        return None
    return round(hops["hop_p90_ms"] / q, 2)


def _misses(p: dict[str, Any], quiet: dict[str, Any] | None) -> list[str]:
    """The targets phase ``p`` missed (see the module doc); none for a pass."""
    why: list[str] = []
    hops, rss, th, cpu = p["hops"], p["rss_mb"], p["threads"], p["cpu_cores"]
    if hops["succeeded"] == 0:
        why.append("no hop succeeded")
    if hops["failed"] or hops["unfinished"]:
        why.append(f"{hops['failed']} hops failed, {hops['unfinished']} unfinished")
    ratio = p["p90_ratio"]
    if ratio is not None and ratio >= P90_RATIO_MAX:
        why.append(f"p90 {ratio}x the quiet p90 (limit {P90_RATIO_MAX:g}x)")
    if rss["delta"] > RSS_DELTA_MAX_MB:
        why.append(f"RSS grew by {rss['delta']} MB (limit {RSS_DELTA_MAX_MB:g})")
    if p["peer_agent_stopped"]:
        why.append(f"the target stopped the peer's ordinary agent: {p['peer_agent_stopped'][0]}")
    if p["accepted_after_s"] is None or p["accepted_after_s"] > ACCEPT_MAX_S:
        why.append(f"no ordinary agent accepted within {ACCEPT_MAX_S:g} s of the attack's end")
    if th["peak"] >= th["peak_ceiling"]:
        why.append(f"peak of {th['peak']} threads, ceiling {th['peak_ceiling']}")
    if th["settled_bound"] is not None and th["settled"] > th["settled_bound"]:
        why.append(f"{th['settled']} threads {th['settled_after_s']} s after the attack, "
                   f"bound {th['settled_bound']} (pools {_pool_sizes(th['pools_settled'])})")
    if quiet is not None and cpu["settled"] > quiet["cpu_cores"]["phase"] + CPU_MARGIN:
        why.append(f"CPU {cpu['settled']:.2f} cores after settling, quiet "
                   f"{quiet['cpu_cores']['phase']:.2f} (limit +{CPU_MARGIN:g})")
    if p["escapes"] is not None and p["escapes"]["ran"]:
        why.append(f"{p['escapes']['ran']} escapes ran: {', '.join(p['escapes']['ran_names'])}")
    return why


def _pool_sizes(pools: dict[str, dict[str, int]]) -> str:
    return ", ".join(f"{k} {v['size']}" for k, v in sorted(pools.items()))
