"""How a federation grows on one machine: N robot processes, one agent, sync mode.

For each N the benchmark runs a federated experiment of N robots (arenas R1..R5 in turn,
Q-learning, average) with the real launcher, robot processes and agent, and reports the wall
time, the median round time (from the agent's round log), the peak resident memory of every
robot process (sampled from ``/proc`` while it runs) and how many rounds ended with every
robot holding the same table.

Each N may run with several itineraries (``chain``: the agent walks the robots and back;
``tree``: it clones itself over a tree of fan-out ``fanout``) and several one-way delays: a
delay puts a :class:`~dfrl.experiments.tools.bench.fault_proxy.FaultProxy` in front of every
robot's platform node, so every hop, clone and message between the nodes costs the delay each
way (the kernel's netem is not needed). ``compare`` gives the tree's median round over the
chain's, per N and delay.
"""

from __future__ import annotations

import statistics
import tempfile
import threading
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from dfrl.experiments.driver.config import ExperimentConfig, RobotSpec
from dfrl.experiments.robot_host.config import Mode
from dfrl.experiments.tools.bench.fault_proxy import FaultProxy

ARENAS = ("r1", "r2", "r3", "r4", "r5")
SAMPLE_S = 0.25


@dataclass(frozen=True)
class ScalePoint:
    """One N of the benchmark."""

    robots: int
    itinerary: str
    fanout: int
    delay_ms: float
    iterations: int
    respite: int
    wall_s: float
    rounds: int
    rounds_planned: int
    rounds_all_equal: int
    round_median_ms: float
    round_max_ms: float
    rss_median_mb: float
    rss_max_mb: float
    identical_every_round: bool
    ok: bool


def _rss_mb(pid: int) -> float | None:
    """Resident memory of a process (MB), None once it is gone."""
    try:
        with open(f"/proc/{pid}/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("VmRSS:"):
                    return int(line.split()[1]) / 1024.0
    except (OSError, ValueError):
        return None
    return None


def config_for(
    n: int, iterations: int, respite: int, seed: int = 1, itinerary: str = "chain", fanout: int = 2
) -> ExperimentConfig:
    """The experiment of one point: ``n`` robots over the five arenas in turn."""
    robots = tuple(RobotSpec(f"r{i + 1}", ARENAS[i % len(ARENAS)]) for i in range(n))
    return ExperimentConfig(
        name=f"scale{n}",
        robots=robots,
        iterations=iterations,
        respite=respite,
        seed=seed,
        mode=Mode.SYNC,
        timeout_s=max(600.0, 30.0 * n),
        itinerary=itinerary,
        fanout=fanout,
    )


class _Proxies:
    """A delaying proxy in front of each robot node, made when the launcher asks for its stop."""

    def __init__(self, delay_s: float) -> None:
        self.delay_s = delay_s
        self._made: dict[tuple[str, int], FaultProxy] = {}

    def route(self, _robot: str, address: tuple[str, int]) -> tuple[str, int]:
        if address not in self._made:
            self._made[address] = FaultProxy(target=address, delay_s=self.delay_s)
        return self._made[address].address

    def close(self) -> None:
        for proxy in self._made.values():
            proxy.close()


def measure(
    n: int,
    iterations: int = 2000,
    respite: int = 500,
    out_dir: Path | None = None,
    itinerary: str = "chain",
    fanout: int = 2,
    delay_ms: float = 0.0,
) -> ScalePoint:
    """Run one point (see the module doc).

    Raises
    ------
    RuntimeError
        The experiment raised (the message says what).
    """
    from dfrl.experiments.driver.launcher import Launcher

    tmp = None
    if out_dir is None:
        tmp = tempfile.TemporaryDirectory(prefix=f"dfrl_scale{n}_")
        out_dir = Path(tmp.name)
    from dfrl.experiments.driver.launcher.spawn import STOP_ROUTE

    launcher = Launcher(
        config_for(n, iterations, respite, itinerary=itinerary, fanout=fanout),
        out_dir,
        progress=None,
    )
    proxies = _Proxies(delay_ms / 1000.0) if delay_ms > 0 else None
    peak: dict[int, float] = {}
    done = threading.Event()
    box: dict[str, Any] = {}

    def sample() -> None:
        while not done.wait(SAMPLE_S):
            for pid in (r.status().pid for r in launcher.robots().values()):
                rss = _rss_mb(pid) if pid is not None else None
                if pid is not None and rss is not None:
                    peak[pid] = max(peak.get(pid, 0.0), rss)

    def target() -> None:
        try:
            if proxies is not None:
                STOP_ROUTE.set(proxies.route)
            box["res"] = launcher.run()
        except BaseException as exc:  # noqa: BLE001 - reported below
            box["exc"] = exc

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    t0 = time.monotonic()
    try:
        runner = threading.Thread(target=target)
        runner.start()
        runner.join()
    finally:
        done.set()
        sampler.join(timeout=5)
        if proxies is not None:
            proxies.close()
        if tmp is not None:
            tmp.cleanup()
    wall = time.monotonic() - t0
    if "exc" in box:
        raise RuntimeError(f"{n} robots: {box['exc']!r}")
    res = box["res"]
    durations = [
        float(r["duration_ms"]) for r in res.rounds if r.get("duration_ms") not in ("", None)
    ]
    rss = sorted(peak.values())
    return ScalePoint(
        robots=n,
        itinerary=itinerary,
        fanout=fanout,
        delay_ms=delay_ms,
        iterations=iterations,
        respite=respite,
        wall_s=round(wall, 2),
        rounds=len(res.rounds),
        rounds_planned=res.config.rounds,
        rounds_all_equal=res.equal_rounds,
        round_median_ms=round(statistics.median(durations), 1) if durations else float("nan"),
        round_max_ms=round(max(durations), 1) if durations else float("nan"),
        rss_median_mb=round(statistics.median(rss), 1) if rss else float("nan"),
        rss_max_mb=round(max(rss), 1) if rss else float("nan"),
        identical_every_round=bool(res.rounds)
        and len(res.rounds) == res.config.rounds
        and res.equal_rounds == res.config.rounds,
        ok=bool(res.ok),
    )


def bench(
    robots: list[int],
    iterations: int = 2000,
    respite: int = 500,
    itineraries: tuple[str, ...] = ("chain",),
    fanout: int = 2,
    delays_ms: tuple[float, ...] = (0.0,),
) -> dict[str, Any]:
    """Every N in ``robots``, smallest first, each with every delay and itinerary; with the
    per-robot round-time growth of each itinerary (without delay, else the first delay) and
    the tree-over-chain round ratio per N and delay.

    Raises
    ------
    ValueError
        An unknown itinerary, a fanout below 2 or a negative delay.
    """
    for it in itineraries:
        if it not in ("chain", "tree"):
            raise ValueError(f"itinerary {it!r}: use chain or tree")
    if fanout < 2:
        raise ValueError(f"fanout {fanout}: a tree needs at least 2")
    if any(d < 0 for d in delays_ms):
        raise ValueError(f"delays {list(delays_ms)}: a delay is >= 0 ms")
    points = [
        measure(n, iterations, respite, itinerary=it, fanout=fanout, delay_ms=d)
        for n in sorted(robots)
        for d in delays_ms
        for it in itineraries
    ]
    growth = []
    for it in itineraries:
        own = [p for p in points if p.itinerary == it and p.delay_ms == delays_ms[0]]
        first = own[0]
        growth += [
            {
                "itinerary": it,
                "delay_ms": p.delay_ms,
                "robots": p.robots,
                "round_ms_per_robot": round(p.round_median_ms / p.robots, 2),
                "round_ratio_vs_linear": round(
                    (p.round_median_ms / first.round_median_ms) / (p.robots / first.robots), 3
                ),
            }
            for p in own
        ]
    compare = []
    if {"chain", "tree"} <= set(itineraries):
        for n in sorted(robots):
            for d in delays_ms:
                c, t = (
                    next(p for p in points if (p.robots, p.delay_ms, p.itinerary) == (n, d, it))
                    for it in ("chain", "tree")
                )
                compare.append(
                    {
                        "robots": n,
                        "delay_ms": d,
                        "chain_ms": c.round_median_ms,
                        "tree_ms": t.round_median_ms,
                        "tree_over_chain": round(t.round_median_ms / c.round_median_ms, 3),
                    }
                )
    return {
        "benchmark": "scale",
        "points": [asdict(p) for p in points],
        "growth": growth,
        "compare": compare,
    }
