"""One full dFRL round (forward and backward over N robot nodes), ms per round.

Starts N robot node processes on loopback (:mod:`dfrl.experiments.robot_node` in benchmark mode:
each holds a random table of ``--entries`` values and serves the agent's requests as soon as
they arrive, no simulation), launches the real itinerary agent
(``platform_pl/agents/dfrl_launch.pl``) for ``--warmup + --rounds`` rounds without rest and
reads the round times from its log (the agent stamps a round's start when it reads the first
robot and its end after writing the first robot back). Checks that every robot holds the
same table after each round. Target: median under 50 ms for 5 nodes and 20,000 entries.
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from dfrl.experiments.config import NodeConfig, RobotSpec
from dfrl.experiments.federation import REPO_ROOT, _Child, agents_dir, swipl_path
from dfrl.experiments.results import read_rounds_log, read_shares, write_rounds_csv

TARGET_MS = 50.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``dfrl bench round``."""
    parser.add_argument("--entries", type=int, default=20000, help="Q-table entries (default 20000)")
    parser.add_argument("--actions", type=int, default=4, help="actions per state (default 4)")
    parser.add_argument("--robots", type=int, default=5, help="robot nodes (default 5)")
    parser.add_argument("--rounds", type=int, default=30, help="timed rounds (default 30)")
    parser.add_argument("--warmup", type=int, default=3, help="untimed rounds first")
    parser.add_argument("--method", default="average", help="aggregation method")
    parser.add_argument("--out", type=Path, default=None,
                        help="keep the node logs and rounds.csv here (default: a temp folder)")
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def bench(entries: int = 20000, actions: int = 4, robots: int = 5, rounds: int = 30,
          warmup: int = 3, method: str = "average", out: Path | None = None) -> dict:
    """Run the benchmark; return its figures."""
    if entries % actions:
        raise ValueError(f"--entries {entries} is not a multiple of --actions {actions}")
    states = entries // actions
    tmp = None
    if out is None:
        tmp = tempfile.TemporaryDirectory(prefix="dfrl_bench_round_")
        out = Path(tmp.name)
    out = out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    children: list[_Child] = []
    try:
        for i in range(robots):
            spec = RobotSpec(f"r{i + 1}", "r1")
            cfg = NodeConfig(robot=spec.id, out_dir=str(out), seed=i, bench_table=[states, actions],
                             events=False, progress_every=0)
            children.append(_Child(spec, cfg, out, lambda *_: None))
        for ch in children:
            if not ch.ready.wait(120) or ch.address is None:
                raise RuntimeError(f"node {ch.robot.id} did not start: {ch.err_tail()}")
        log = out / "rounds_bench.log"
        if log.exists():
            log.unlink()
        total = warmup + rounds
        launch = {"name": "bench", "method": method, "rounds": total, "rest_s": 0.0,
                  "rounds_log": str(log), "token": 1111, "timeout_s": 60.0,
                  "itinerary": [{"host": ch.address[0], "port": ch.address[1], "robot": ch.robot.id}
                                for ch in children]}
        launch_file = out / "launch_bench.json"
        launch_file.write_text(json.dumps(launch), encoding="utf-8")
        t0 = time.monotonic()
        proc = subprocess.run([swipl_path(), "-q", str(agents_dir() / "dfrl_launch.pl"),
                               str(launch_file)], capture_output=True, text=True, timeout=60,
                              cwd=REPO_ROOT)
        if proc.returncode != 0:
            raise RuntimeError(f"agent launch failed: {proc.stderr or proc.stdout}")
        deadline = time.monotonic() + max(120.0, total * 2.0)
        agent_log = read_rounds_log(log, "bench")
        while agent_log.finished is None and time.monotonic() < deadline:
            time.sleep(0.1)
            agent_log = read_rounds_log(log, "bench")
        wall = time.monotonic() - t0
        if agent_log.finished is None:
            raise RuntimeError(f"the agent did not finish {total} rounds in time "
                               f"({len(agent_log.rounds)} done)")
    finally:
        for ch in children:
            ch.close_stdin()
        for ch in children:
            try:
                ch.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                ch.kill()
            ch.finish()
    ids = [ch.robot.id for ch in children]
    shares = {rid: read_shares(out / f"shares_{rid}.csv") for rid in ids}
    rows = write_rounds_csv(out / "rounds.csv", [agent_log], ids, shares)
    timed = [r for r in agent_log.rounds if r.round > warmup]
    ms = sorted(r.duration_ms for r in timed)
    result = {
        "benchmark": "round", "robots": robots, "entries": entries, "shape": [states, actions],
        "method": method, "rounds": len(timed), "warmup": warmup,
        "median_ms": round(statistics.median(ms), 2),
        "p90_ms": round(ms[min(len(ms) - 1, int(0.9 * len(ms)))], 2),
        "min_ms": round(ms[0], 2), "max_ms": round(ms[-1], 2),
        "hops": timed[0].hops, "bytes_carried": timed[0].bytes,
        "all_equal_rounds": sum(1 for r in rows if r["all_equal"]), "total_rounds": len(rows),
        "wall_s": round(wall, 2), "target_ms": TARGET_MS,
        "log_problems": agent_log.unreadable + agent_log.aborted,
        "meets_target": statistics.median(ms) < TARGET_MS,
    }
    if tmp is not None:
        tmp.cleanup()
    return result


def run_cli(args: argparse.Namespace) -> int:
    try:
        r = bench(args.entries, args.actions, args.robots, args.rounds, args.warmup, args.method,
                  args.out)
    except (RuntimeError, ValueError) as exc:
        print(f"dfrl bench round: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(r))
    else:
        print(f"{r['robots']} nodes, {r['entries']} entries, {r['method']}: one round "
              f"(forward + backward, {r['hops']} hops, {r['bytes_carried']} bytes carried) "
              f"median {r['median_ms']} ms, p90 {r['p90_ms']} ms over {r['rounds']} rounds "
              f"(target < {TARGET_MS:g} ms); identical tables after "
              f"{r['all_equal_rounds']}/{r['total_rounds']} rounds")
    return 0
