"""Agent table read+write through the bridge while the simulation runs (ms, median/p90).

An agent-like Prolog thread repeatedly reads a robot's Q-table with ``read_table/3`` and
writes it back with ``write_table/3``; the Python main thread steps a pybullet world flat out
and calls :meth:`pybridge.Bridge.serve_pending` after every control step, as a robot
node does. Each codec (``fts``: fast_term_serialized bytes, ``text``: float text) is timed
in turn. The table must come back bit for bit. Target: read+write under 5 ms for 20,000
entries (fts).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

import dfrl.pybridge as pybridge_package

if TYPE_CHECKING:
    from dfrl.pybridge import StaticTable

TARGET_MS = 5.0

#: The agent side of the benchmark (shipped with the bridge).
BRIDGE_BENCH: Path = Path(pybridge_package.__file__).resolve().parent / "bridge_bench.pl"


class BenchSim:
    """What the main loop steps between two ``serve_pending`` calls."""

    def __init__(self, kind: str, bodies: int, physics_steps: int, seed: int) -> None:
        self.kind = kind
        self.physics_steps = physics_steps
        self.client = None
        self.trainer = None
        if kind == "epuck":
            from dfrl.robots.training import Trainer, TrainerConfig

            self.trainer = Trainer(TrainerConfig(seed=seed))
        if kind == "pybullet":
            import pybullet_data

            from dfrl.arenas.pybullet_quiet import load

            pybullet = load()

            self.p = pybullet
            self.client = pybullet.connect(pybullet.DIRECT)
            pybullet.setAdditionalSearchPath(
                pybullet_data.getDataPath(), physicsClientId=self.client
            )
            pybullet.setGravity(0, 0, -9.81, physicsClientId=self.client)
            pybullet.loadURDF("plane.urdf", physicsClientId=self.client)
            rng = np.random.default_rng(seed)
            box = pybullet.createCollisionShape(
                pybullet.GEOM_BOX, halfExtents=[0.05] * 3, physicsClientId=self.client
            )
            for _ in range(bodies):
                pos = [*rng.uniform(-0.5, 0.5, 2), rng.uniform(0.1, 2.0)]
                pybullet.createMultiBody(0.1, box, basePosition=pos, physicsClientId=self.client)

    def step(self) -> None:
        if self.trainer is not None:
            self.trainer.step()
        if self.client is not None:
            for _ in range(self.physics_steps):
                self.p.stepSimulation(physicsClientId=self.client)

    def close(self) -> None:
        if self.trainer is not None:
            self.trainer.close()
        if self.client is not None:
            self.p.disconnect(physicsClientId=self.client)


def _stats(values: list[float]) -> dict[str, float]:
    arr = np.asarray(values, dtype=np.float64)
    if arr.size == 0:
        return {"median_ms": float("nan"), "p90_ms": float("nan")}
    return {
        "median_ms": round(float(np.median(arr)), 4),
        "p90_ms": round(float(np.percentile(arr, 90)), 4),
    }


def run_codec(
    node: Any, robot: StaticTable, sim: BenchSim, codec: str, warmup: int, repeats: int
) -> dict[str, Any]:
    """Time ``repeats`` read+write pairs with ``codec`` while ``sim`` steps."""
    from dfrl.pybridge import Atom, Term, Var

    node.codec = codec
    before = robot.q_table
    node.call(
        "thread_create",
        Term("bench_table_round_trips", Atom("bench_robot"), warmup, repeats, []),
        Var(),
        [Term("alias", Atom("bench_agent")), Term("detached", Atom("true"))],
        module="bridge_bench",
    )
    serve_ms: list[float] = []
    step_ms: list[float] = []
    deadline = time.monotonic() + 120
    result = None
    while time.monotonic() < deadline:
        t0 = time.perf_counter()
        sim.step()
        t1 = time.perf_counter()
        n = node.serve_pending()
        t2 = time.perf_counter()
        step_ms.append((t1 - t0) * 1000)
        if n:
            serve_ms.append((t2 - t1) * 1000 / n)
            continue
        sol = node.call("bench_result", Var("R"), module="bridge_bench")
        if sol is not None:
            result = sol["R"]
            break
    if result is None:
        raise RuntimeError("the benchmark agent did not finish in 120 s")
    if result.name == "error":
        raise RuntimeError(f"the benchmark agent failed: {result.args[0]!r}")
    totals, gets, sets = (list(x) for x in result.args)
    exact = bool(np.array_equal(robot.q_table.view(np.int64), before.view(np.int64)))
    out = {
        "codec": codec,
        **_stats(totals),
        "get": _stats(gets),
        "set": _stats(sets),
        "serve_per_request": _stats(serve_ms),
        "sim_step": _stats(step_ms),
        "pairs": len(totals),
        "bit_exact": exact,
    }
    return out


def bench(
    entries: int = 20000,
    actions: int = 4,
    repeats: int = 50,
    warmup: int = 5,
    codec: str = "both",
    sim: str = "pybullet",
    bodies: int = 30,
    physics_steps: int = 1,
    seed: int = 0,
) -> dict[str, Any]:
    """Run the benchmark; return its figures (``codecs``: one entry per codec timed).

    Raises
    ------
    RuntimeError
        The benchmark agent failed or did not finish.
    """
    from dfrl.pybridge import Atom, Bridge, StaticTable

    n_actions = max(1, actions)
    n_states = max(1, entries // n_actions)
    robot = StaticTable((n_states, n_actions), seed)
    world = BenchSim(sim, bodies, physics_steps, seed)
    node = Bridge(request_timeout=60.0)
    try:
        node.call("use_module", Atom(str(BRIDGE_BENCH)))
        node.register_robot("bench_robot", robot, shape=robot.shape)
        codecs = ["fts", "text"] if codec == "both" else [codec]
        if "fts" in codecs and not node.self_test_report.fts_ok:
            codecs.remove("fts")
        results = {c: run_codec(node, robot, world, c, warmup, repeats) for c in codecs}
    finally:
        node.close()
        world.close()
    main = results.get("fts") or next(iter(results.values()))
    return {
        "benchmark": "bridge",
        "entries": n_states * n_actions,
        "shape": [n_states, n_actions],
        "sim": sim,
        "codec": main["codec"],
        "median_ms": main["median_ms"],
        "p90_ms": main["p90_ms"],
        "target_ms": TARGET_MS,
        "meets_target": bool(main["median_ms"] < TARGET_MS),
        "self_test": node.self_test_report.detail,
        "codecs": results,
    }
