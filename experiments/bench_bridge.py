"""Agent table read+write through the bridge while the simulation runs (ms, median/p90).

An agent-like Prolog thread repeatedly reads a robot's Q-table with ``get_qtable/3`` and
writes it back with ``set_qtable/3``; the Python main thread steps a pybullet world flat out
and calls :meth:`pybridge.RobotNode.serve_pending` after every control step, as a robot
node does. Each codec (``fts``: fast_term_serialized bytes, ``text``: float text) is timed
in turn. The table must come back bit for bit. Target: read+write under 5 ms for 20,000
entries (fts).
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

import numpy as np

TARGET_MS = 5.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``dfrl bench bridge``."""
    parser.add_argument("--entries", type=int, default=20000, help="Q-table entries (default 20000)")
    parser.add_argument("--actions", type=int, default=4, help="actions per state (default 4)")
    parser.add_argument("--repeats", type=int, default=50, help="timed read+write pairs per codec")
    parser.add_argument("--warmup", type=int, default=5, help="untimed pairs first")
    parser.add_argument("--codec", choices=["fts", "text", "both"], default="both")
    parser.add_argument("--sim", choices=["pybullet", "epuck", "none"], default="pybullet",
                        help="what the main loop steps between two serve_pending calls: a pybullet "
                             "world of falling boxes, a training e-puck (robots.training.Trainer: "
                             "one 64 ms control step of sense, learn, act), or nothing")
    parser.add_argument("--bodies", type=int, default=30, help="falling boxes in the pybullet world")
    parser.add_argument("--physics-steps", type=int, default=1,
                        help="pybullet steps per control step (serve_pending once per control step)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", action="store_true", help="print one JSON object")


class _Robot:
    """Table provider for the benchmark (what a learner offers the bridge)."""

    def __init__(self, n_states: int, n_actions: int, seed: int) -> None:
        rng = np.random.default_rng(seed)
        self._q = rng.standard_normal((n_states, n_actions))
        self._visits = rng.integers(0, 100, (n_states, n_actions), dtype=np.int64)

    @property
    def q_table(self) -> np.ndarray:
        return self._q.copy()

    @property
    def visits(self) -> np.ndarray:
        return self._visits.copy()

    def set_q_table(self, table: np.ndarray) -> None:
        self._q = np.array(table, dtype=np.float64)


class _Sim:
    def __init__(self, kind: str, bodies: int, physics_steps: int, seed: int) -> None:
        self.kind = kind
        self.physics_steps = physics_steps
        self.client = None
        self.trainer = None
        if kind == "epuck":
            from dfrl.robots.training import Trainer, TrainerConfig

            self.trainer = Trainer(TrainerConfig(seed=seed))
        if kind == "pybullet":
            import pybullet
            import pybullet_data

            self.p = pybullet
            self.client = pybullet.connect(pybullet.DIRECT)
            pybullet.setAdditionalSearchPath(pybullet_data.getDataPath(), physicsClientId=self.client)
            pybullet.setGravity(0, 0, -9.81, physicsClientId=self.client)
            pybullet.loadURDF("plane.urdf", physicsClientId=self.client)
            rng = np.random.default_rng(seed)
            box = pybullet.createCollisionShape(pybullet.GEOM_BOX, halfExtents=[0.05] * 3,
                                                physicsClientId=self.client)
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
    return {"median_ms": round(float(np.median(arr)), 4), "p90_ms": round(float(np.percentile(arr, 90)), 4)}


def _run_codec(node: Any, robot: _Robot, sim: _Sim, codec: str, args: argparse.Namespace) -> dict[str, Any]:
    from dfrl.pybridge import Atom, Term, Var

    node.codec = codec
    before = robot.q_table
    node.call("thread_create",
              Term("bench_table_round_trips", Atom("bench_robot"), args.warmup, args.repeats, []),
              Var(), [Term("alias", Atom("bench_agent")), Term("detached", Atom("true"))],
              module="bridge_bench")
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
    out = {"codec": codec, **_stats(totals), "get": _stats(gets), "set": _stats(sets),
           "serve_per_request": _stats(serve_ms), "sim_step": _stats(step_ms),
           "pairs": len(totals), "bit_exact": exact}
    return out


def run(args: argparse.Namespace) -> int:
    """Run the benchmark; print figures (JSON with ``--json``). Exit 0 if the table stays
    bit-exact (the speed target is reported, not enforced)."""
    from dfrl.pybridge import RobotNode

    n_actions = max(1, args.actions)
    n_states = max(1, args.entries // n_actions)
    robot = _Robot(n_states, n_actions, args.seed)
    sim = _Sim(args.sim, args.bodies, args.physics_steps, args.seed)
    node = RobotNode(request_timeout=60.0)
    try:
        node.call("use_module", _atom(Path(__file__).resolve().parents[1] / "pybridge" / "bridge_bench.pl"))
        node.register_robot("bench_robot", robot)
        codecs = ["fts", "text"] if args.codec == "both" else [args.codec]
        if "fts" in codecs and not node.self_test_report.fts_ok:
            codecs.remove("fts")
        results = {c: _run_codec(node, robot, sim, c, args) for c in codecs}
    finally:
        node.close()
        sim.close()
    main = results.get("fts") or next(iter(results.values()))
    report = {
        "benchmark": "bridge",
        "entries": n_states * n_actions,
        "shape": [n_states, n_actions],
        "sim": args.sim,
        "codec": main["codec"],
        "median_ms": main["median_ms"],
        "p90_ms": main["p90_ms"],
        "target_ms": TARGET_MS,
        "meets_target": bool(main["median_ms"] < TARGET_MS),
        "self_test": node.self_test_report.detail,
        "codecs": results,
    }
    if args.json:
        print(json.dumps(report))
    else:
        print(f"bridge: {report['entries']} entries {report['shape']}, sim={args.sim}")
        for c, r in results.items():
            print(f"  {c:4s} read+write median {r['median_ms']:.3f} ms  p90 {r['p90_ms']:.3f} ms  "
                  f"(get {r['get']['median_ms']:.3f}, set {r['set']['median_ms']:.3f}, "
                  f"host serve/request {r['serve_per_request']['median_ms']:.3f} ms, "
                  f"sim step {r['sim_step']['median_ms']:.3f} ms)  bit-exact={r['bit_exact']}")
        print(f"  target < {TARGET_MS} ms: {'met' if report['meets_target'] else 'NOT met'}")
    return 0 if all(r["bit_exact"] for r in results.values()) else 1


def _atom(path: Path) -> Any:
    from dfrl.pybridge import Atom

    return Atom(str(path))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_arguments(parser)
    raise SystemExit(run(parser.parse_args()))
