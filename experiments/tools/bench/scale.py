"""How a federation grows on one machine: N robot processes, one agent, sync mode.

For each N the benchmark runs a federated experiment of N robots (arenas R1..R5 in turn,
Q-learning, average) with the real launcher, robot processes and agent, and reports the wall
time, the median round time (from the agent's round log), the peak resident memory of every
robot process (sampled from ``/proc`` while it runs) and how many rounds ended with every
robot holding the same table.
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

ARENAS = ("r1", "r2", "r3", "r4", "r5")
SAMPLE_S = 0.25


@dataclass(frozen=True)
class ScalePoint:
    """One N of the benchmark."""

    robots: int
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


def config_for(n: int, iterations: int, respite: int, seed: int = 1) -> ExperimentConfig:
    """The experiment of one point: ``n`` robots over the five arenas in turn."""
    robots = tuple(RobotSpec(f"r{i + 1}", ARENAS[i % len(ARENAS)]) for i in range(n))
    return ExperimentConfig(name=f"scale{n}", robots=robots, iterations=iterations,
                            respite=respite, seed=seed, mode="sync",
                            timeout_s=max(600.0, 30.0 * n))


def measure(n: int, iterations: int = 2000, respite: int = 500,
            out_dir: Path | None = None) -> ScalePoint:
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
    launcher = Launcher(config_for(n, iterations, respite), out_dir, progress=None)
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
        if tmp is not None:
            tmp.cleanup()
    wall = time.monotonic() - t0
    if "exc" in box:
        raise RuntimeError(f"{n} robots: {box['exc']!r}")
    res = box["res"]
    durations = [float(r["duration_ms"]) for r in res.rounds if r.get("duration_ms") not in ("", None)]
    rss = sorted(peak.values())
    return ScalePoint(
        robots=n, iterations=iterations, respite=respite, wall_s=round(wall, 2),
        rounds=len(res.rounds), rounds_planned=res.config.rounds,
        rounds_all_equal=res.equal_rounds,
        round_median_ms=round(statistics.median(durations), 1) if durations else float("nan"),
        round_max_ms=round(max(durations), 1) if durations else float("nan"),
        rss_median_mb=round(statistics.median(rss), 1) if rss else float("nan"),
        rss_max_mb=round(max(rss), 1) if rss else float("nan"),
        ok=bool(res.ok))


def bench(robots: list[int], iterations: int = 2000, respite: int = 500) -> dict[str, Any]:
    """Every N in ``robots``, smallest first; with the per-robot round-time growth."""
    points = [measure(n, iterations, respite) for n in sorted(robots)]
    first = points[0]
    growth = [{"robots": p.robots,
               "round_ms_per_robot": round(p.round_median_ms / p.robots, 2),
               "round_ratio_vs_linear": round((p.round_median_ms / first.round_median_ms)
                                              / (p.robots / first.robots), 3)}
              for p in points]
    return {"benchmark": "scale", "points": [asdict(p) for p in points], "growth": growth}
