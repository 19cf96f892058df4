"""Simulation speed, pybullet beside the batched simulator: robot-steps per second per core.

Every point is one simulator, one robot count, with or without learning, timed in this process
on one core (pybullet and the numba kernels are single-threaded: ``cpu_s`` is at most
``wall_s``); ``steps_per_s_per_core`` is robot-steps over wall seconds, ``steps_per_cpu_s``
over the process's CPU seconds (the same on an idle core; higher when other processes share
it). The points alternate (for each robot count and learning mode: pybullet, then batched), so
both see the same machine.

* **pybullet**, learning: a :class:`dfrl.robots.training.Trainer` per robot (its own DIRECT
  client, sensing, reward, learner update), stepped round-robin; without learning: an
  :class:`dfrl.robots.env.EPuckEnv` per robot taking uniform random actions (reset when its
  episode ends). Its cost grows with the robots, so a point times at most ``pybullet_budget``
  robot-steps (steps per robot scaled down, and the warm-up with them), and at most
  ``pybullet_live`` clients are alive at once (about 28 MB each: 1,024 would not fit in memory):
  more robots are built, warmed up, timed and closed group after group.
* **batched**, learning: :meth:`dfrl.robots.batched.training.BatchedTrainer.run`; without
  learning: :meth:`dfrl.robots.batched.world.BatchedWorld.wander`, uniform random actions drawn
  inside the compiled loop (robots whose episode ends respawn). The first call (numba compiles,
  or loads its on-disk cache) is timed apart as ``compile_s``; then the warm-up, then the
  timed steps.
"""

from __future__ import annotations

import os
import platform
import time
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from dfrl.robots.training import Trainer, TrainerConfig
from dfrl.robots.world import SimConfig

#: The simulators measured, in the order of a point pair.
SIMS: tuple[str, ...] = ("pybullet", "batched")
#: Timed robot-steps of one pybullet point, at most (about 15 s on this machine).
PYBULLET_BUDGET: int = 40_000
#: pybullet clients alive at once, at most.
PYBULLET_LIVE: int = 64


def pybullet_steps(robots: int, steps: int, budget: int) -> int:
    """Steps per robot of a pybullet point: ``steps``, fewer when ``robots * steps`` exceeds
    ``budget`` robot-steps, at least 1."""
    return max(1, min(steps, budget // robots))


class _RandomEPuck:
    """An :class:`EPuckEnv` taking uniform random actions, reset when its episode ends."""

    def __init__(self, config: TrainerConfig) -> None:
        from dfrl.robots.env import EPuckEnv

        self.env = EPuckEnv(arena=config.arena, config=config.env_config())
        self.env.reset(seed=config.seed)
        self.rng = np.random.default_rng(config.seed)
        self.n = int(self.env.action_space.n)

    def step(self) -> None:
        _, _, terminated, truncated, _ = self.env.step(int(self.rng.integers(self.n)))
        if terminated or truncated:
            self.env.reset()

    def close(self) -> None:
        self.env.close()


class _RandomBatch:
    """A :class:`BatchedWorld` whose robots take uniform random actions drawn inside the
    compiled loop (:meth:`BatchedWorld.wander`); a robot whose episode ends respawns."""

    def __init__(self, configs: Sequence[TrainerConfig]) -> None:
        from dfrl.robots.batched.world import BatchedWorld

        rngs = [np.random.default_rng(c.seed) for c in configs]
        self.world = BatchedWorld(configs[0].env_config(), [c.arena for c in configs], rngs)
        self.policy = [np.random.default_rng([c.seed, 1]) for c in configs]
        for i in range(self.world.n):
            self.world.start(i)

    def run(self, steps: int) -> None:
        self.world.wander(steps, self.policy)  # actions drawn in the compiled loop


def _point(
    sim: str,
    robots: int,
    learning: bool,
    steps: int,
    warmup: int,
    wall: float,
    cpu: float,
    control_dt: float,
    **extra: Any,
) -> dict[str, Any]:
    rate = steps * robots / wall if wall > 0 else float("inf")
    per_cpu = steps * robots / cpu if cpu > 0 else float("inf")
    return {
        "sim": sim,
        "robots": robots,
        "learning": learning,
        "steps": steps,
        "warmup": warmup,
        "robot_steps": steps * robots,
        "wall_s": round(wall, 9),
        "cpu_s": round(cpu, 9),
        "steps_per_s_per_core": round(rate, 1),
        "steps_per_cpu_s": round(per_cpu, 1),
        "realtime_factor_per_core": round(rate * control_dt, 1),
        **extra,
    }


def measure_pybullet(
    config: TrainerConfig,
    robots: int,
    steps: int,
    warmup: int,
    learning: bool,
    live: int = PYBULLET_LIVE,
) -> dict[str, Any]:
    """Time ``steps`` control steps of each of ``robots`` pybullet robots, at most ``live``
    alive at once, stepped round-robin after ``warmup`` untimed steps.

    Returns
    -------
    dict
        The point (see :func:`bench`), with ``live`` and ``setup_s`` (building the robots,
        not timed).
    """
    make: Callable[[TrainerConfig], Any] = Trainer if learning else _RandomEPuck
    wall = cpu = setup = 0.0
    for first in range(0, robots, live):
        t0 = time.perf_counter()
        group = [
            make(config.replace(seed=config.seed + first + k))
            for k in range(min(live, robots - first))
        ]
        setup += time.perf_counter() - t0
        try:
            for _ in range(warmup):
                for r in group:
                    r.step()
            c0, t0 = time.process_time(), time.perf_counter()
            for _ in range(steps):
                for r in group:
                    r.step()
            wall += time.perf_counter() - t0
            cpu += time.process_time() - c0
        finally:
            for r in group:
                r.close()
    return _point(
        "pybullet",
        robots,
        learning,
        steps,
        warmup,
        wall,
        cpu,
        config.sim.control_dt,
        live=min(live, robots),
        setup_s=round(setup, 3),
    )


def measure_batched(
    config: TrainerConfig, robots: int, steps: int, warmup: int, learning: bool
) -> dict[str, Any]:
    """Time ``steps`` control steps of ``robots`` robots in the batched simulator, after its
    first call (``compile_s``) and ``warmup`` untimed steps.

    Returns
    -------
    dict
        The point (see :func:`bench`), with ``setup_s`` (building the batch, including the
        motion table measured in pybullet once per process) and ``compile_s``.
    """
    from dfrl.robots.batched.training import BatchedTrainer

    configs = [config.replace(seed=config.seed + i) for i in range(robots)]
    t0 = time.perf_counter()
    batch = BatchedTrainer(configs) if learning else _RandomBatch(configs)
    setup = time.perf_counter() - t0
    t0 = time.perf_counter()
    batch.run(1)
    compile_s = time.perf_counter() - t0
    batch.run(max(0, warmup - 1))
    c0, t0 = time.process_time(), time.perf_counter()
    batch.run(steps)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    return _point(
        "batched",
        robots,
        learning,
        steps,
        warmup,
        wall,
        cpu,
        config.sim.control_dt,
        setup_s=round(setup, 3),
        compile_s=round(compile_s, 3),
    )


def ratios(points: Sequence[dict[str, Any]]) -> list[dict[str, Any]]:
    """``batched / pybullet`` of ``steps_per_s_per_core`` for each (robots, learning) measured
    in both."""
    rate = {(p["sim"], p["robots"], p["learning"]): p["steps_per_s_per_core"] for p in points}
    out = []
    for (sim, robots, learning), batched in rate.items():
        pybullet = rate.get(("pybullet", robots, learning))
        if sim == "batched" and pybullet:
            out.append(
                {
                    "robots": robots,
                    "learning": learning,
                    "batched_over_pybullet": round(batched / pybullet, 1),
                }
            )
    return out


def _scaling(points: Sequence[dict[str, Any]], dt: float) -> list[dict[str, Any]]:
    """The pybullet learning points in the fields of the older report (one row per count)."""
    rows = []
    for p in points:
        if p["sim"] == "pybullet" and p["learning"]:
            rate = p["steps_per_s_per_core"]
            rows.append(
                {
                    "robots": p["robots"],
                    "wall_s": round(p["wall_s"], 3),
                    "steps_per_s": rate,
                    "steps_per_s_per_robot": round(rate / p["robots"], 1),
                    "realtime_factor": round(rate * dt, 1),
                    "realtime_factor_per_robot": round(rate * dt / p["robots"], 1),
                }
            )
    return rows


def bench(
    arena: str = "r4",
    algo: str = "qlearning",
    steps: int = 5000,
    robots: Sequence[int] | None = None,
    physics_dt: float | None = None,
    control_dt: float | None = None,
    warmup: int = 200,
    sims: Sequence[str] = SIMS,
    pybullet_budget: int = PYBULLET_BUDGET,
    pybullet_live: int = PYBULLET_LIVE,
) -> dict[str, Any]:
    """Measure each robot count of ``robots``, with and without learning, in each of ``sims``.

    Parameters
    ----------
    steps, warmup : int
        Timed and untimed steps per robot (pybullet's scaled down by ``pybullet_budget``).
    sims : sequence of {"pybullet", "batched"}

    Returns
    -------
    dict
        ``points``: one dict per point with ``sim``, ``robots``, ``learning``, ``steps`` and
        ``warmup`` (per robot), ``robot_steps``, ``wall_s``, ``cpu_s``,
        ``steps_per_s_per_core``, ``steps_per_cpu_s``, ``realtime_factor_per_core``,
        ``setup_s``, pybullet's ``live``, batched's ``compile_s``; ``ratios``
        (:func:`ratios`); the settings; and, when
        pybullet was measured, the older report's ``steps_per_s``, ``realtime_factor`` (pybullet
        learning at the first count) and ``scaling`` (its learning points).

    Raises
    ------
    ValueError
        Inconsistent physics and control rates, an unknown simulator, counts below 1, or a
        learner the batched simulator does not have.
    """
    robots = list(robots or [1, 64, 1024])
    unknown = sorted(set(sims) - set(SIMS))
    if unknown or not sims:
        raise ValueError(f"simulators must be among {list(SIMS)}, got {list(sims)}")
    if min(robots) < 1 or steps < 1 or warmup < 1 or pybullet_budget < 1 or pybullet_live < 1:
        raise ValueError("robots, steps, warmup, pybullet budget and live robots must be >= 1")
    d = SimConfig()
    sim = SimConfig(
        control_dt=d.control_dt if control_dt is None else control_dt,
        physics_dt=d.physics_dt if physics_dt is None else physics_dt,
    )
    config = TrainerConfig(arena=arena, algo=algo, seed=0, sim=sim)
    if "batched" in sims:
        from dfrl.robots.batched.training import shared_env

        shared_env([config])  # a learner it lacks fails here, not later
    points = []
    for n in robots:
        for learning in (True, False):
            for name in (s for s in SIMS if s in sims):
                if name == "pybullet":
                    points.append(
                        measure_pybullet(
                            config,
                            n,
                            pybullet_steps(n, steps, pybullet_budget),
                            pybullet_steps(n, warmup, max(1, pybullet_budget // 10)),
                            learning,
                            pybullet_live,
                        )
                    )
                else:
                    points.append(measure_batched(config, n, steps, warmup, learning))
    out: dict[str, Any] = {
        "benchmark": "sim",
        "arena": arena,
        "algo": algo,
        "control_dt": sim.control_dt,
        "physics_dt": sim.physics_dt,
        "substeps": sim.substeps,
        "steps": steps,
        "warmup": warmup,
        "sims": [s for s in SIMS if s in sims],
        "robot_counts": robots,
        "cores": 1,
        "pybullet_budget": pybullet_budget,
        "pybullet_live": pybullet_live,
        "points": points,
        "ratios": ratios(points),
        "cpu": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
    }
    scaling = _scaling(points, sim.control_dt)
    if scaling:
        out.update(
            robots=scaling[0]["robots"],
            steps_per_s=scaling[0]["steps_per_s"],
            realtime_factor=scaling[0]["realtime_factor"],
            scaling=scaling,
        )
    return out
