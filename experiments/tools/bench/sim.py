"""Simulation + learning speed: control steps per second and real-time factor in one process.

Each robot is a full :class:`dfrl.robots.training.Trainer` (its own pybullet DIRECT client, the
arena, sensing, reward, learner update); the robots of one process are stepped round-robin on
one core. ``realtime_factor`` is simulated seconds per wall-clock second.
"""
from __future__ import annotations

import os
import platform
import time
from typing import Any

from dfrl.robots.training import Trainer, TrainerConfig
from dfrl.robots.world import SimConfig


def measure(config: TrainerConfig, robots: int, steps: int, warmup: int = 200) -> dict[str, Any]:
    """Time ``steps`` control steps of each of ``robots`` trainers stepped round-robin.

    Returns
    -------
    dict
        ``robots``, ``steps_per_s`` (all robots together), ``steps_per_s_per_robot``,
        ``realtime_factor`` (together) and ``realtime_factor_per_robot``, ``wall_s``.
    """
    trainers = [Trainer(config.replace(seed=config.seed + i)) for i in range(robots)]
    try:
        for _ in range(warmup):
            for t in trainers:
                t.step()
        t0 = time.perf_counter()
        for _ in range(steps):
            for t in trainers:
                t.step()
        wall = time.perf_counter() - t0
    finally:
        for t in trainers:
            t.close()
    total = steps * robots / wall
    dt = config.sim.control_dt
    return {
        "robots": robots,
        "wall_s": round(wall, 3),
        "steps_per_s": round(total, 1),
        "steps_per_s_per_robot": round(total / robots, 1),
        "realtime_factor": round(total * dt, 1),
        "realtime_factor_per_robot": round(total * dt / robots, 1),
    }


def bench(arena: str = "r4", algo: str = "qlearning", steps: int = 5000,
          robots: list[int] | None = None, physics_dt: float | None = None,
          control_dt: float | None = None, warmup: int = 200) -> dict[str, Any]:
    """Measure each robot count of ``robots`` (the first is the headline figure).

    Raises
    ------
    ValueError
        Inconsistent physics and control rates.
    """
    d = SimConfig()
    sim = SimConfig(control_dt=d.control_dt if control_dt is None else control_dt,
                    physics_dt=d.physics_dt if physics_dt is None else physics_dt)
    config = TrainerConfig(arena=arena, algo=algo, seed=0, sim=sim)
    rows = [measure(config, n, steps, warmup) for n in (robots or [1, 2, 4])]
    head = rows[0]
    return {
        "benchmark": "sim",
        "arena": arena,
        "algo": algo,
        "control_dt": sim.control_dt,
        "physics_dt": sim.physics_dt,
        "substeps": sim.substeps,
        "steps": steps,
        "robots": head["robots"],
        "steps_per_s": head["steps_per_s"],
        "realtime_factor": head["realtime_factor"],
        "scaling": rows,
        "cpu": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
    }
