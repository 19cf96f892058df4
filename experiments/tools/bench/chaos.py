"""Chaos: agents moving among 3 store-backed nodes through fault proxies, under random faults.

Three ``swipl`` node processes (``chaos_node.pl node``, each with ``store(DIR)`` and short
timeouts) on loopback; between every ordered pair a :class:`FaultProxy`, through which the
agents of one node reach the other. A few hopper agents move continuously (a 20-120 ms pause,
then a move to a random other node). Faults, one at a time, from the list of issue 8: kill -9 of
the destination right after its staged reply or during the transfer, kill -9 of the source
before its decision or after its commit decision (its commit frame dropped), kill -9 of a random
node at a random moment (each killed node is restarted with its store), dropped transfer,
staged and commit frames, a stalled connection and a delay longer than every timeout, SIGSTOP of
a node past the timeouts (then SIGCONT), a cut link (then mended).

After each fault the agents are paused and the nodes left to settle (bounded wait); a census
(``custody_agents/2`` on every node, through ``chaos_node.pl console``) then counts each agent's
copies: ``lost`` (no copy anywhere), ``doubled`` (two live copies), ``unsettled`` (still staged,
departing or in doubt when the wait ends), summed over the censuses (one after each fault, one
at the end; a double that persists counts at every census). Required: all three 0. The census
is known to catch real faults: with the destination starting an agent whose source has no
record (instead of presumed abort) 6 faults gave ``doubled`` 12; with it discarding an agent
whose source does not answer, 6 faults gave ``lost`` 4.
"""

from __future__ import annotations

import json
import os
import random
import selectors
import signal
import socket
import statistics
import subprocess
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

from dfrl.experiments import processes
from dfrl.experiments.tokens import env_with_tokens, new_secret
from dfrl.experiments.tools.bench.fault_proxy import DROP, PASS, STALL, Action, FaultProxy

SCRIPT = Path(__file__).resolve().parent / "chaos_node.pl"
TOKEN = new_secret()
"""The nodes' token, this process's own, handed to them in the environment (never argv)."""
REPLY_TIMEOUT_S = 1.5  # the nodes' reply_timeout (chaos_node.pl)
PAST_TIMEOUTS_S = 2.5  # SIGSTOP, stall and delay last this long
FAULT_KINDS = (
    "kill_dest_after_staged",
    "kill_dest_during_transfer",
    "kill_source_before_decision",
    "kill_source_after_commit",
    "kill_random",
    "drop_transfer",
    "drop_staged",
    "drop_commit",
    "stall",
    "delay",
    "sigstop",
    "cut",
)


class NodeProcess:
    """One node process: started (again) on its port with its store; log in the work folder."""

    def __init__(self, index: int, port: int, work: Path, routes: dict[int, int]) -> None:
        self.index = index
        self.port = port
        self.store = work / f"store{index}"
        self.log = work / f"node{index}.log"
        self.routes = ",".join(f"{j}={p}" for j, p in sorted(routes.items()))
        self.proc: subprocess.Popen | None = None
        self.starts = 0

    def start(self, agents: list[str], timeout: float = 20.0) -> None:
        args = [
            processes.swipl(),
            "-q",
            str(SCRIPT),
            "node",
            str(self.port),
            str(self.store),
            self.routes,
        ] + ([",".join(agents)] if agents else [])
        offset = self.log.stat().st_size if self.log.exists() else 0
        with open(self.log, "ab") as log:
            self.proc = processes.start(
                args, stdout=log, stderr=subprocess.STDOUT, env=env_with_tokens([TOKEN])
            )
        self.starts += 1
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            with open(self.log, "rb") as f:
                f.seek(offset)
                if b"CHAOS listening" in f.read():
                    return
            if self.proc.poll() is not None:
                break
            time.sleep(0.05)
        raise RuntimeError(f"node {self.index} did not start; see {self.log}")

    def kill(self) -> None:
        """The fault ``kill -9``: no grace, the node's store as it was."""
        if self.proc is not None and self.proc.poll() is None:
            os.kill(self.proc.pid, signal.SIGKILL)
            self.proc.wait(10)

    def stop(self) -> None:
        """The end of the benchmark: let a stopped node go on, then stop it."""
        if self.proc is not None:
            self.signal(signal.SIGCONT)
            processes.stop(self.proc)

    def signal(self, sig: int) -> None:
        if self.proc is not None and self.proc.poll() is None:
            os.kill(self.proc.pid, sig)


class ChaosConsole:
    """``chaos_node.pl console``: JSON lines, each answer awaited with a deadline."""

    def __init__(self) -> None:
        self.proc = processes.start(
            [processes.swipl(), "-q", str(SCRIPT), "console"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            bufsize=1,
            env=env_with_tokens([TOKEN]),
        )
        self.sel = selectors.DefaultSelector()
        assert self.proc.stdout is not None
        self.sel.register(self.proc.stdout, selectors.EVENT_READ)

    def ask(self, request: dict, timeout: float = 20.0) -> dict:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(json.dumps(request) + "\n")
        self.proc.stdin.flush()
        if not self.sel.select(timeout):
            raise RuntimeError(f"console gave no answer to {request} in {timeout} s")
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError("console ended")
        return json.loads(line)

    def close(self) -> None:
        if self.proc.stdin:
            self.proc.stdin.close()
        processes.wait_or_stop(self.proc, 5.0)


class Trigger:
    """A proxy rule that fires once at a protocol point: the transfer frame (up, binary), the
    staged reply (the down text frame after it) or the commit (the up text frame after that)."""

    def __init__(self, point: str, action: Action, on_fire: Callable[[], None]) -> None:
        self.point = point
        self.action = action
        self.on_fire = on_fire
        self.fired = threading.Event()
        self.done = False
        self.last: dict[int, str] = {}

    def __call__(self, direction: str, conn: int, frame: int, kind: str, length: int) -> Action:
        last = self.last.get(conn)
        if direction == "up" and kind == "B":
            point = "transfer"
        elif direction == "down" and kind == "T" and last == "transfer":
            point = "staged"
        elif direction == "up" and kind == "T" and last == "staged":
            point = "commit"
        else:
            point = "other"
        self.last[conn] = point
        if point != self.point or self.done:
            return PASS
        self.done = True
        self.on_fire()
        self.fired.set()  # after on_fire: the injector then sees what it did
        return self.action


class _Chaos:
    def __init__(
        self, work: Path, seed: int, n_nodes: int, n_agents: int, settle_timeout: float
    ) -> None:
        self.rng = random.Random(seed)
        self.settle_timeout = settle_timeout
        ports = [_free_port() for _ in range(n_nodes)]
        self.proxies = {
            (i, j): FaultProxy(("127.0.0.1", ports[j]))
            for i in range(n_nodes)
            for j in range(n_nodes)
            if i != j
        }
        self.nodes = [
            NodeProcess(
                i,
                ports[i],
                work,
                {j: self.proxies[(i, j)].address[1] for j in range(n_nodes) if j != i},
            )
            for i in range(n_nodes)
        ]
        self.agents = [f"a{k}" for k in range(n_agents)]
        self.console: ChaosConsole | None = None

    def start(self) -> None:
        for node in self.nodes:
            node.start([a for k, a in enumerate(self.agents) if k % len(self.nodes) == node.index])
        self.console = ChaosConsole()

    def close(self) -> None:
        if self.console is not None:
            self.console.close()
        for node in self.nodes:
            node.stop()
        for proxy in self.proxies.values():
            proxy.close()

    # -- faults ------------------------------------------------------------------------------
    def inject(self, kind: str) -> bool:
        """Inject one fault and undo its cause (restart, SIGCONT, mend); True if it hit its
        protocol point (a trigger that found no frame in time falls back to its kill/drop
        at a random moment)."""
        i, j = self.rng.sample(range(len(self.nodes)), 2)
        proxy = self.proxies[(i, j)]
        dead: list[NodeProcess] = []

        def kill(node: NodeProcess) -> None:
            node.kill()
            dead.append(node)

        points = {
            "kill_dest_after_staged": ("staged", PASS, lambda: kill(self.nodes[j])),
            "kill_dest_during_transfer": ("transfer", PASS, lambda: kill(self.nodes[j])),
            "kill_source_before_decision": ("staged", PASS, lambda: kill(self.nodes[i])),
            "kill_source_after_commit": ("commit", DROP, lambda: kill(self.nodes[i])),
            "drop_transfer": ("transfer", DROP, lambda: None),
            "drop_staged": ("staged", DROP, lambda: None),
            "drop_commit": ("commit", DROP, lambda: None),
        }
        hit = True
        if kind in points or kind == "stall":
            point, action, fire = points.get(
                kind, (self.rng.choice(["transfer", "staged", "commit"]), STALL, lambda: None)
            )
            trigger = Trigger(point, action, fire)
            proxy.rule(trigger)
            hit = trigger.fired.wait(5.0)
            proxy.rule(None)
            if not hit and kind.startswith("kill"):
                fire()
            if kind == "stall":
                time.sleep(PAST_TIMEOUTS_S)
                proxy.cut()
                proxy.mend()
        elif kind == "kill_random":
            time.sleep(self.rng.uniform(0, 1))
            kill(self.nodes[self.rng.randrange(len(self.nodes))])
        elif kind == "delay":
            proxy.delay(PAST_TIMEOUTS_S - 0.5 + REPLY_TIMEOUT_S / 2)
            time.sleep(PAST_TIMEOUTS_S)
            proxy.delay(0)
        elif kind == "sigstop":
            node = self.nodes[self.rng.randrange(len(self.nodes))]
            node.signal(signal.SIGSTOP)
            time.sleep(PAST_TIMEOUTS_S)
            node.signal(signal.SIGCONT)
        elif kind == "cut":
            back = self.proxies[(j, i)]
            proxy.cut()
            back.cut()
            time.sleep(self.rng.uniform(1.0, 2.0))
            proxy.mend()
            back.mend()
        else:
            raise ValueError(f"unknown fault kind {kind!r}")
        for node in dead:
            time.sleep(self.rng.uniform(0.1, 0.8))
            node.start([])
        return hit

    # -- census ------------------------------------------------------------------------------
    def census(self) -> dict:
        """Pause the agents, wait (bounded) until every agent has one live copy, count."""
        assert self.console is not None
        ports = [n.port for n in self.nodes]
        self.console.ask({"op": "pause", "ports": ports, "paused": True})
        t0 = time.monotonic()
        deadline = t0 + self.settle_timeout
        while True:
            answer = self.console.ask({"op": "census", "ports": ports})
            copies: dict[str, list[str]] = {a: [] for a in self.agents}
            hops: dict[str, int] = {}
            all_ok = all(n.get("ok") for n in answer["nodes"])
            for n in answer["nodes"]:
                for a in n.get("agents", []):
                    copies.setdefault(a["name"], []).append(a["status"])
                    hops[a["name"]] = max(hops.get(a["name"], 0), a["hops"])
            settled = all_ok and all(
                len(s) == 1 and s[0] in ("running", "idle") for s in copies.values()
            )
            if settled or time.monotonic() > deadline:
                break
            time.sleep(0.2)
        settle_s = time.monotonic() - t0
        self.console.ask({"op": "pause", "ports": ports, "paused": False})
        lost = doubled = unsettled = 0
        for statuses in copies.values():
            live = sum(s in ("running", "idle") for s in statuses)
            if not statuses and all_ok:
                lost += 1
            elif live > 1:
                doubled += 1
            elif not (len(statuses) == 1 and live == 1):
                unsettled += 1
        return {
            "lost": lost,
            "doubled": doubled,
            "unsettled": unsettled,
            "settle_s": settle_s,
            "moves": sum(hops.values()),
            "copies": copies,
        }


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def run(
    faults: int = 100,
    seed: int = 0,
    nodes: int = 3,
    agents: int = 4,
    settle_timeout: float = 30.0,
    workdir: Path | None = None,
    progress: Callable[[int, str, dict], None] | None = None,
    kinds: tuple[str, ...] = FAULT_KINDS,
) -> dict:
    """Run the benchmark; return its figures (see the module doc). ``kinds`` are drawn in
    seeded shuffled rounds, so each kind occurs ``faults / len(kinds)`` times (+1).

    Raises
    ------
    ValueError
        Bad arguments.
    ExperimentError
        swipl is not installed.
    RuntimeError
        A node or the console did not start or answer.
    """
    if faults < 0 or nodes < 2 or agents < 1:
        raise ValueError("faults >= 0, nodes >= 2 and agents >= 1 are required")
    unknown = set(kinds) - set(FAULT_KINDS)
    if unknown or not kinds:
        raise ValueError(f"unknown fault kinds {sorted(unknown)}; choose from {FAULT_KINDS}")
    t_start = time.monotonic()
    tmp = None
    if workdir is None:
        tmp = tempfile.TemporaryDirectory(prefix="dfrl_chaos_")
        workdir = Path(tmp.name)
    workdir.mkdir(parents=True, exist_ok=True)
    rng = random.Random(seed)
    order: list[str] = []
    while len(order) < faults:
        batch = list(kinds)
        rng.shuffle(batch)
        order += batch
    order = order[:faults]
    by_kind = {k: {"faults": 0, "hit": 0, "lost": 0, "doubled": 0, "unsettled": 0} for k in kinds}
    totals = {"lost": 0, "doubled": 0, "unsettled": 0}
    settles: list[float] = []
    chaos = _Chaos(workdir, seed, nodes, agents, settle_timeout)
    try:
        chaos.start()
        time.sleep(1.0)
        for n, kind in enumerate(order, 1):
            hit = chaos.inject(kind)
            c = chaos.census()
            settles.append(c["settle_s"])
            k = by_kind[kind]
            k["faults"] += 1
            k["hit"] += int(hit)
            for key in totals:
                k[key] += c[key]
                totals[key] += c[key]
            if progress is not None:
                progress(n, kind, c)
        final = chaos.census()
        for key in totals:
            totals[key] += final[key]
    finally:
        chaos.close()
        if tmp is not None:
            tmp.cleanup()
    return {
        "faults": faults,
        **totals,
        "seed": seed,
        "nodes": nodes,
        "agents": agents,
        "moves": final["moves"],
        "restarts": sum(n.starts - 1 for n in chaos.nodes),
        "settle_s_median": round(statistics.median(settles), 3) if settles else 0.0,
        "settle_s_max": round(max(settles), 3) if settles else 0.0,
        "wall_s": round(time.monotonic() - t_start, 1),
        "by_kind": by_kind,
    }
