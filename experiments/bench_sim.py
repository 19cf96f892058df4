"""Simulation + learning speed: control steps per second and real-time factor in one process.

Each robot is a full :class:`dfrl.robots.training.Trainer` (its own pybullet DIRECT client, the
arena, sensing, reward, learner update); the robots of one process are stepped round-robin on
one core. ``realtime_factor`` is simulated seconds per wall-clock second.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from typing import Any

from dfrl.robots.learners import LEARNERS
from dfrl.robots.training import Trainer, TrainerConfig
from dfrl.robots.world import SimConfig


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``dfrl bench sim``."""
    parser.add_argument("--steps", type=int, default=5000, help="timed control steps per robot")
    parser.add_argument("--robots", type=int, nargs="+", default=[1, 2, 4],
                        help="robots per process to measure (the first is the headline figure)")
    parser.add_argument("--arena", default="r4")
    parser.add_argument("--algo", choices=sorted(LEARNERS), default="qlearning")
    parser.add_argument("--physics-dt", type=float, default=SimConfig().physics_dt)
    parser.add_argument("--control-dt", type=float, default=SimConfig().control_dt)
    parser.add_argument("--warmup", type=int, default=200, help="untimed steps per robot first")
    parser.add_argument("--json", action="store_true", help="print JSON")


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


def run(args: argparse.Namespace) -> int:
    """Run the benchmark and print its figures (JSON with ``--json``)."""
    try:
        sim = SimConfig(control_dt=args.control_dt, physics_dt=args.physics_dt)
    except ValueError as exc:
        print(f"dfrl bench sim: error: {exc}", file=sys.stderr)
        return 2
    config = TrainerConfig(arena=args.arena, algo=args.algo, seed=0, sim=sim)
    rows = [measure(config, n, args.steps, args.warmup) for n in args.robots]
    head = rows[0]
    out = {
        "benchmark": "sim",
        "arena": args.arena,
        "algo": args.algo,
        "control_dt": sim.control_dt,
        "physics_dt": sim.physics_dt,
        "substeps": sim.substeps,
        "steps": args.steps,
        "robots": head["robots"],
        "steps_per_s": head["steps_per_s"],
        "realtime_factor": head["realtime_factor"],
        "scaling": rows,
        "cpu": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
    }
    if args.json:
        print(json.dumps(out, indent=2))
    else:
        print(f"sim bench: {args.algo} in {args.arena}, control {sim.control_dt * 1000:g} ms, "
              f"physics {sim.physics_dt * 1000:g} ms ({sim.substeps} substeps), {args.steps} steps")
        print(f"{'robots':>6} {'steps/s':>9} {'per robot':>10} {'x real time':>12} {'per robot':>10}")
        for r in rows:
            print(f"{r['robots']:>6} {r['steps_per_s']:>9.0f} {r['steps_per_s_per_robot']:>10.0f} "
                  f"{r['realtime_factor']:>12.0f} {r['realtime_factor_per_robot']:>10.0f}")
    return 0
