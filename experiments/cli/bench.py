"""``dfrl bench migrate|sim|round|bridge|chaos|scale|hostile|fuzz|vs-flower``: run a benchmark and
print its figures (JSON with ``--json``). The benchmarks themselves are
:mod:`dfrl.experiments.tools.bench`; ``hostile``'s options and output are :mod:`.bench_hostile`,
``vs-flower``'s :mod:`.bench_vs_flower`."""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path
from typing import Any

from dfrl.experiments.cli import bench_faults, bench_fidelity, bench_hostile, bench_vs_flower
from dfrl.experiments.science import fidelity
from dfrl.experiments.tools.bench import (
    bridge,
    chaos,
    hop_timeline,
    hostile,
    migrate,
    round as round_bench,
)
from dfrl.experiments.tools.bench import faults, fuzz, scale, sim, vs_flower


# -- migrate ---------------------------------------------------------------------------------
def add_migrate_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--floats",
        type=int,
        nargs="+",
        default=[0, 1000, 10000, 100000],
        help="payload sizes (floats in the agent's payload)",
    )
    parser.add_argument(
        "--payload",
        choices=migrate.PAYLOADS,
        default="packed",
        help="how the agent carries the floats: packed, as the dFRL agent "
        "carries tables, or as a Prolog list (default: packed; the naive "
        "text hop always writes a list)",
    )
    parser.add_argument("--hops", type=int, default=50, help="timed hops per size")
    parser.add_argument("--warmup", type=int, default=2, help="untimed hops first")
    parser.add_argument("--json", action="store_true", help="print one JSON object per size")
    parser.add_argument(
        "--tls",
        default=None,
        metavar="DIR",
        help="also measure over mutual TLS with the node certificate in DIR "
        "(ca.crt, node.crt, node.key), beside plaintext (default: "
        "plaintext only)",
    )
    parser.add_argument(
        "--rounds",
        type=int,
        default=3,
        help="with --tls: alternating plaintext/TLS runs per size; with "
        "--against: alternating runs of each checkout (default 3). "
        "With two or more, each pair's ratio and the 95%% interval of "
        "their geometric mean are printed too (how far the figure moves "
        "with the machine)",
    )
    parser.add_argument(
        "--against",
        default=None,
        metavar="DIR",
        help="compare with the checkout at DIR (e.g. a git worktree of an older "
        "commit): its hop and this one's, run alternately",
    )
    parser.add_argument(
        "--timeline",
        action="store_true",
        help="also run each size with the platform's hop probes compiled in and "
        "print where a hop's time goes: the median time of each point of "
        "the hand-over from the call of move_agent (not with --tls or "
        "--against)",
    )


def cmd_migrate(args: argparse.Namespace) -> int:
    if args.timeline and (args.against or args.tls):
        print(
            "dfrl bench migrate: --timeline goes with neither --tls nor --against", file=sys.stderr
        )
        return 2
    if args.against:
        return _migrate_against(args)
    if args.tls:
        return _migrate_tls(args)
    for n in args.floats:
        try:
            result = migrate.run(n, args.hops, args.warmup, payload=args.payload)
            probed = (
                hop_timeline.measure(n, args.hops, args.warmup, args.payload)
                if args.timeline
                else None
            )
        except (ValueError, RuntimeError, FileNotFoundError) as exc:
            print(f"dfrl bench migrate: {exc}", file=sys.stderr)
            return 1
        if args.json:
            out = asdict(result)
            if probed is not None:
                out["timeline"] = asdict(probed)
            print(json.dumps(out))
        else:
            naive = (
                ""
                if result.naive_median_ms is None
                else f"  naive text hop {result.naive_median_ms:8.3f} ms  "
                f"ratio {result.naive_ratio:.3f}"
            )
            print(
                f"floats={n:>7}  median {result.median_ms:8.3f} ms  p10 {result.p10_ms:8.3f}  "
                f"p90 {result.p90_ms:8.3f}  min {result.min_ms:8.3f}  max {result.max_ms:8.3f}  "
                f"(hops={result.hops}){naive}"
            )
            if probed is not None:
                print(hop_timeline.table(probed))
        sys.stdout.flush()
    return 0


def _per_size(
    args: argparse.Namespace, compare: Callable[[int], Any], line: Callable[[int, Any], str]
) -> int:
    """One comparison per payload size of ``--floats``: its JSON, or ``line(n, result)``."""
    for n in args.floats:
        try:
            cmp = compare(n)
        except (ValueError, RuntimeError, FileNotFoundError) as exc:
            print(f"dfrl bench migrate: {exc}", file=sys.stderr)
            return 2 if isinstance(exc, ValueError) else 1
        print(json.dumps(asdict(cmp)) if args.json else line(n, cmp))
        sys.stdout.flush()
    return 0


def _migrate_against(args: argparse.Namespace) -> int:
    def line(n: int, cmp: Any) -> str:
        ratios = (
            ""
            if cmp.this_naive_ratio is None or cmp.other_naive_ratio is None
            else f"  naive ratio {cmp.this_naive_ratio:.3f} (against {cmp.other_naive_ratio:.3f})"
        )
        pairs = "" if cmp.pairs is None else f"  run by run {cmp.pairs}"
        return (
            f"floats={n:>7}  this median {cmp.this_median_ms:8.3f} ms  against "
            f"{cmp.other_median_ms:8.3f} ms  this/against {cmp.this_over_other:.3f}  "
            f"({cmp.runs} runs each, alternating){ratios}{pairs}"
        )

    return _per_size(
        args,
        lambda n: migrate.compare_checkouts(
            n, args.hops, args.against, args.rounds, args.warmup, args.payload
        ),
        line,
    )


def _records(direct: bool | None) -> str:
    """Where the TLS records went (tls.pl's direct write), if the benchmark said."""
    if direct is None:
        return ""
    return (
        "  records: straight to the socket"
        if direct
        else "  records: through library(ssl)'s stream, byte by byte"
    )


def _tls_rounds(rounds: Any) -> str:
    """The TLS cost round by round: its spread and the 95% interval of its mean."""
    if rounds is None:
        return ""
    costs = ", ".join(f"{r - 1:+.0%}" for r in rounds.ratios)
    if math.isnan(rounds.low):
        return f"  rounds {costs}"
    return (
        f"  rounds {costs}; mean {rounds.mean - 1:+.1%}, 95% interval "
        f"{rounds.low - 1:+.1%} to {rounds.high - 1:+.1%}"
    )


def _migrate_tls(args: argparse.Namespace) -> int:
    def line(n: int, cmp: Any) -> str:
        naive = (
            ""
            if cmp.plain.naive_median_ms is None
            else f"  naive text hop {cmp.plain.naive_median_ms:8.3f} ms  "
            f"ratio {cmp.plain.naive_ratio:.3f}"
        )
        return (
            f"floats={n:>7}  plaintext median {cmp.plain.median_ms:8.3f} ms  "
            f"TLS median {cmp.tls.median_ms:8.3f} ms  TLS cost {cmp.tls_cost:+.1%}  "
            f"(hops={cmp.tls.hops} each){_tls_rounds(cmp.rounds)}{naive}"
            f"{_records(cmp.tls.tls_direct)}"
        )

    return _per_size(
        args,
        lambda n: migrate.compare_tls(
            n, args.hops, args.tls, args.warmup, args.rounds, args.payload
        ),
        line,
    )


# -- sim -------------------------------------------------------------------------------------
def add_sim_arguments(parser: argparse.ArgumentParser) -> None:
    from dfrl.robots.learners import LEARNERS
    from dfrl.robots.world import SimConfig

    parser.add_argument(
        "--steps",
        type=int,
        default=5000,
        help="timed control steps per robot (pybullet: fewer, see --pybullet-budget)",
    )
    parser.add_argument(
        "--robots", type=int, nargs="+", default=[1, 64, 1024], help="robot counts to measure"
    )
    parser.add_argument(
        "--sims",
        nargs="+",
        choices=list(sim.SIMS),
        default=list(sim.SIMS),
        help="simulators to measure, alternating point by point",
    )
    parser.add_argument("--arena", default="r4", help="arena of every robot")
    parser.add_argument(
        "--algo",
        choices=sorted(LEARNERS),
        default="qlearning",
        help="learner (batched: qlearning or sarsa)",
    )
    parser.add_argument(
        "--physics-dt", type=float, default=SimConfig().physics_dt, help="physics step (s)"
    )
    parser.add_argument(
        "--control-dt", type=float, default=SimConfig().control_dt, help="control step (s)"
    )
    parser.add_argument("--warmup", type=int, default=200, help="untimed steps per robot first")
    parser.add_argument(
        "--pybullet-budget",
        type=int,
        default=sim.PYBULLET_BUDGET,
        help="timed robot-steps of a pybullet point at most: steps (and "
        "warm-up, a tenth) per robot scaled down to fit",
    )
    parser.add_argument(
        "--pybullet-live",
        type=int,
        default=sim.PYBULLET_LIVE,
        help="pybullet clients alive at once at most (about 28 MB each); more "
        "robots are measured group after group",
    )
    parser.add_argument("--json", action="store_true", help="print JSON")


def cmd_sim(args: argparse.Namespace) -> int:
    try:
        out = sim.bench(
            args.arena,
            args.algo,
            args.steps,
            args.robots,
            args.physics_dt,
            args.control_dt,
            args.warmup,
            args.sims,
            args.pybullet_budget,
            args.pybullet_live,
        )
    except ValueError as exc:
        print(f"dfrl bench sim: error: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    print(
        f"sim bench: {args.algo} in {args.arena}, control {out['control_dt'] * 1000:g} ms, "
        f"physics {out['physics_dt'] * 1000:g} ms ({out['substeps']} substeps); one process "
        f"on one core: steps/s per core = robot-steps / wall s"
    )
    if "pybullet" in out["sims"]:
        print(
            f"pybullet: at most {out['pybullet_budget']:,} timed robot-steps per point (steps "
            f"per robot scaled down), at most {out['pybullet_live']} robots alive at once"
        )
    if "batched" in out["sims"]:
        print(
            "batched: timed after its first call (compile s: numba compiles or loads its "
            "cache) and the warm-up"
        )
    print(
        f"{'sim':<9} {'robots':>6} {'learning':>8} {'steps':>6} {'robot-steps':>11} "
        f"{'wall s':>8} {'steps/s/core':>12} {'per CPU s':>10} {'x real time':>11} "
        f"{'compile s':>9}"
    )
    for p in out["points"]:
        compile_s = f"{p['compile_s']:>9.2f}" if "compile_s" in p else f"{'':>9}"
        print(
            f"{p['sim']:<9} {p['robots']:>6} {'yes' if p['learning'] else 'no':>8} "
            f"{p['steps']:>6} {p['robot_steps']:>11} {p['wall_s']:>8.2f} "
            f"{p['steps_per_s_per_core']:>12.0f} {p['steps_per_cpu_s']:>10.0f} "
            f"{p['realtime_factor_per_core']:>11.0f} {compile_s}"
        )
    for r in out["ratios"]:
        print(
            f"batched / pybullet, {r['robots']} robots, "
            f"{'learning' if r['learning'] else 'no learning'}: {r['batched_over_pybullet']:g}"
        )
    return 0


def add_table_shape_arguments(parser: argparse.ArgumentParser) -> None:
    """``--entries`` and ``--actions``: the shape of the benchmark's Q-tables."""
    parser.add_argument(
        "--entries", type=int, default=20000, help="Q-table entries (default 20000)"
    )
    parser.add_argument("--actions", type=int, default=4, help="actions per state (default 4)")


# -- round -----------------------------------------------------------------------------------
def add_round_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--learner",
        choices=round_bench.LEARNERS,
        default="table",
        help="what each robot holds: a random Q-table of --entries (table, the "
        "default) or a random parameter vector of that learner's network "
        "(linear, dqn; carried as parameters, FedAvg weighted by samples)",
    )
    parser.add_argument(
        "--entries", type=int, default=None, help="Q-table entries (default 20000; a table only)"
    )
    parser.add_argument(
        "--actions", type=int, default=None, help="actions per state (default 4; a table only)"
    )
    parser.add_argument(
        "--robots",
        type=int,
        nargs="+",
        default=[5],
        help="robot processes, one benchmark per count (default 5)",
    )
    parser.add_argument("--rounds", type=int, default=30, help="timed rounds (default 30)")
    parser.add_argument("--warmup", type=int, default=3, help="untimed rounds first")
    parser.add_argument("--method", default="average", help="aggregation method")
    parser.add_argument(
        "--itinerary",
        choices=list(round_bench.ITINERARIES),
        default="chain",
        help="the agent walks the robots and back (chain) or clones itself over a tree",
    )
    parser.add_argument(
        "--fanout", type=int, default=2, help="children per stop of a tree itinerary"
    )
    parser.add_argument(
        "--hop-hops",
        type=int,
        default=20,
        help="migrate hops timed beside the round, with a payload of --entries floats (0: none)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help="keep the node logs and rounds.csv here, in a subfolder per robot "
        "count when there are several (default: a temp folder)",
    )
    parser.add_argument(
        "--trace",
        type=Path,
        default=None,
        metavar="DIR",
        help="time the platform's steps in every robot process (their files "
        "robot-<id>.jsonl in DIR) and print the sum per step; a traced "
        "round is slower, its figures compare steps (default: no trace)",
    )
    parser.add_argument(
        "--json", action="store_true", help="print one JSON object per robot count, one a line"
    )


def cmd_round(args: argparse.Namespace) -> int:
    if args.learner != "table" and (args.entries is not None or args.actions is not None):
        print(
            f"dfrl bench round: --entries and --actions size a table; a {args.learner} "
            f"network's size is its layout (drop them, or use --learner table)",
            file=sys.stderr,
        )
        return 2
    entries = 20000 if args.entries is None else args.entries
    actions = 4 if args.actions is None else args.actions
    status = 0
    for n in args.robots:
        out = args.out / f"robots{n}" if args.out is not None and len(args.robots) > 1 else args.out
        try:
            trace = (
                None
                if args.trace is None
                else args.trace / f"robots{n}"
                if len(args.robots) > 1
                else args.trace
            )
            r = round_bench.bench(
                entries,
                actions,
                n,
                args.rounds,
                args.warmup,
                args.method,
                out,
                args.hop_hops,
                args.learner,
                trace,
                itinerary=args.itinerary,
                fanout=args.fanout,
            )
        except (RuntimeError, ValueError) as exc:
            print(f"dfrl bench round: {n} robots: {exc}", file=sys.stderr)
            return 1
        if args.json:
            print(json.dumps(r), flush=True)
        else:
            what = (
                f"{r['entries']} entries"
                if "entries" in r
                else f"{r['learner']} parameters ({r['floats']} floats, {r['payload_bytes']} bytes)"
            )
            held = "tables" if "entries" in r else "parameters"
            print(
                f"{r['robots']} nodes, {what}, {r['method']}, {r['itinerary']}: one round "
                f"(forward + backward, {r['hops']} hops, {r['bytes_carried']} bytes carried) "
                f"median {r['median_ms']} ms, p90 {r['p90_ms']} ms over {r['rounds']} rounds "
                f"(target < {round_bench.TARGET_MS:g} ms); identical {held} after "
                f"{r['all_equal_rounds']}/{r['total_rounds']} rounds",
                flush=True,
            )
            if r["hop_median_ms"] is not None:
                print(
                    f"  its hops: {r['hops']} x {r['hop_median_ms']} ms (bench migrate, "
                    f"{r['hop_floats']} floats, same run): the round takes "
                    f"{r['round_over_hops']} x its hops",
                    flush=True,
                )
            for t in r.get("steps", [])[:25]:
                print(
                    f"  step {t['step']:<28} {t['calls']:6d} calls  median {t['median_ms']:8.3f} "
                    f"ms  p90 {t['p90_ms']:8.3f} ms  total {t['total_ms']:9.1f} ms",
                    flush=True,
                )
        for problem in r["log_problems"]:
            print(f"dfrl bench round: agent log: {problem}", file=sys.stderr)
        for skip in r["skipped"]:
            print(f"dfrl bench round: skipped: {skip}", file=sys.stderr)
        if r["all_equal_rounds"] < r["total_rounds"] or r["log_problems"] or r["skipped"]:
            print(
                f"dfrl bench round: {n} robots: tables differed after "
                f"{r['total_rounds'] - r['all_equal_rounds']} of {r['total_rounds']} rounds, "
                f"or the agent's log had problems, or rounds skipped robots",
                file=sys.stderr,
            )
            status = 1
    return status


# -- bridge ----------------------------------------------------------------------------------
def add_bridge_arguments(parser: argparse.ArgumentParser) -> None:
    add_table_shape_arguments(parser)
    parser.add_argument("--repeats", type=int, default=50, help="timed read+write pairs per codec")
    parser.add_argument("--warmup", type=int, default=5, help="untimed pairs first")
    parser.add_argument(
        "--codec", choices=["fts", "text", "both"], default="both", help="table codec(s) to time"
    )
    parser.add_argument(
        "--sim",
        choices=["pybullet", "epuck", "none"],
        default="pybullet",
        help="what the main loop steps between two serve_pending calls: a pybullet "
        "world of falling boxes, a training e-puck (robots.training.Trainer: "
        "one 64 ms control step of sense, learn, act), or nothing",
    )
    parser.add_argument(
        "--bodies", type=int, default=30, help="falling boxes in the pybullet world"
    )
    parser.add_argument(
        "--physics-steps",
        type=int,
        default=1,
        help="pybullet steps per control step (serve_pending once per control step)",
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the tables and the world")
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def cmd_bridge(args: argparse.Namespace) -> int:
    """Exit 0 if the table stays bit-exact (the speed target is reported, not enforced)."""
    try:
        report = bridge.bench(
            args.entries,
            args.actions,
            args.repeats,
            args.warmup,
            args.codec,
            args.sim,
            args.bodies,
            args.physics_steps,
            args.seed,
        )
    except RuntimeError as exc:
        print(f"dfrl bench bridge: {exc}", file=sys.stderr)
        return 1
    results = report["codecs"]
    if args.json:
        print(json.dumps(report))
    else:
        print(f"bridge: {report['entries']} entries {report['shape']}, sim={args.sim}")
        for c, r in results.items():
            print(
                f"  {c:4s} read+write median {r['median_ms']:.3f} ms  p90 {r['p90_ms']:.3f} ms  "
                f"(get {r['get']['median_ms']:.3f}, set {r['set']['median_ms']:.3f}, "
                f"host serve/request {r['serve_per_request']['median_ms']:.3f} ms, "
                f"sim step {r['sim_step']['median_ms']:.3f} ms)  bit-exact={r['bit_exact']}"
            )
        print(f"  target < {bridge.TARGET_MS} ms: {'met' if report['meets_target'] else 'NOT met'}")
    return 0 if all(r["bit_exact"] for r in results.values()) else 1


# -- chaos -----------------------------------------------------------------------------------
def add_chaos_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--faults", type=int, default=100, help="faults to inject (default 100)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the fault schedule")
    parser.add_argument("--agents", type=int, default=4, help="hopping agents (default 4)")
    parser.add_argument(
        "--settle-timeout",
        type=float,
        default=30.0,
        help="longest wait for the nodes to settle after a fault (s)",
    )
    parser.add_argument(
        "--keep",
        type=Path,
        default=None,
        help="keep the node logs and stores here (default: a temp folder)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def cmd_chaos(args: argparse.Namespace) -> int:
    """Exit 0 only if no agent was lost, doubled or left unsettled."""

    def progress(n: int, kind: str, c: dict) -> None:
        if not args.json:
            print(
                f"{n:4d} {kind:28s} settled in {c['settle_s']:5.2f} s  lost {c['lost']} "
                f"doubled {c['doubled']} unsettled {c['unsettled']}",
                flush=True,
            )

    try:
        r = chaos.run(
            args.faults,
            args.seed,
            agents=args.agents,
            settle_timeout=args.settle_timeout,
            workdir=args.keep,
            progress=progress,
        )
    except (ValueError, RuntimeError) as exc:  # ExperimentError is a RuntimeError
        print(f"dfrl bench chaos: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(r))
    else:
        print(
            f"{r['faults']} faults, {r['moves']} moves, {r['restarts']} restarts: lost "
            f"{r['lost']}, doubled {r['doubled']}, unsettled {r['unsettled']} "
            f"({r['wall_s']} s)"
        )
    return 0 if r["lost"] == r["doubled"] == r["unsettled"] == 0 else 1


# -- scale -----------------------------------------------------------------------------------
def add_scale_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--robots",
        type=int,
        nargs="+",
        default=[2, 8, 32],
        help="robot counts to run (default: 2 8 32)",
    )
    parser.add_argument(
        "--iterations", type=int, default=2000, help="iterations per robot (default: 2000)"
    )
    parser.add_argument(
        "--respite", type=int, default=500, help="iterations between shares (default: 500)"
    )
    parser.add_argument(
        "--itinerary",
        nargs="+",
        choices=["chain", "tree"],
        default=["chain"],
        help="itineraries to run at each robot count (default: chain)",
    )
    parser.add_argument(
        "--fanout", type=int, default=2, help="children per stop of a tree itinerary (default: 2)"
    )
    parser.add_argument(
        "--delay-ms",
        type=float,
        nargs="+",
        default=[0.0],
        help="one-way delays on every link between the robots' nodes, each "
        "run at every count (a proxy per node; default: 0)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def cmd_scale(args: argparse.Namespace) -> int:
    """Exit 0 only if every point ran all its rounds with identical tables."""
    try:
        r = scale.bench(
            args.robots,
            args.iterations,
            args.respite,
            itineraries=tuple(args.itinerary),
            fanout=args.fanout,
            delays_ms=tuple(args.delay_ms),
        )
    except (ValueError, RuntimeError) as exc:
        print(f"dfrl bench scale: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(r))
    else:
        for p in r["points"]:
            print(
                f"{p['robots']:3d} robots, {p['itinerary']:5s} delay {p['delay_ms']:g} ms: "
                f"wall {p['wall_s']:7.1f} s, round median "
                f"{p['round_median_ms']:8.1f} ms, RSS per robot median {p['rss_median_mb']:6.1f} "
                f"MB (max {p['rss_max_mb']:.1f}), rounds with identical tables "
                f"{p['rounds_all_equal']}/{p['rounds_planned']}"
            )
        for c in r["compare"]:
            print(
                f"{c['robots']:3d} robots, delay {c['delay_ms']:g} ms: tree/chain round "
                f"{c['tree_over_chain']:.3f} ({c['tree_ms']:.0f} / {c['chain_ms']:.0f} ms)"
            )
    ok = all(p["ok"] and p["rounds_all_equal"] == p["rounds_planned"] for p in r["points"])
    return 0 if ok else 1


def add_fuzz_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--frames", type=int, default=20_000, help="mutated frames to send")
    parser.add_argument(
        "--seed",
        type=int,
        default=None,
        help="seed of every random choice (default: drawn, and printed)",
    )
    parser.add_argument(
        "--checkout",
        type=Path,
        default=None,
        metavar="DIR",
        help="run the target node of the dfrl checkout at DIR (e.g. main's, "
        "as the control); default: this one",
    )
    parser.add_argument("--max-s", type=float, default=3600.0, help="time limit of the run")
    parser.add_argument(
        "--max-crashes",
        type=int,
        default=20,
        help="stop after that many crashes (the node is restarted after each)",
    )
    parser.add_argument(
        "--prolog-check",
        action="store_true",
        help="the node checks bodies in Prolog (as without its C library)",
    )
    parser.add_argument("--json", action="store_true", help="print the result as JSON")


def cmd_fuzz(args: argparse.Namespace) -> int:
    cfg = fuzz.FuzzConfig(
        frames=args.frames,
        seed=args.seed,
        checkout=args.checkout,
        max_s=args.max_s,
        max_crashes=args.max_crashes,
        native_check=not args.prolog_check,
    )

    def progress(k: int, r: fuzz.FuzzResult) -> None:
        print(f"[fuzz] {k} frames, {len(r.crashes)} crashes", file=sys.stderr, flush=True)

    result = fuzz.run(cfg, progress=None if args.json else progress)
    if args.json:
        print(json.dumps(result.as_dict()))
    else:
        print(
            f"seed {result.seed}: {result.frames} frames in {result.seconds} s, "
            f"{len(result.crashes)} crashes (first at frame {result.first_crash_frame}), "
            f"node pids {result.node_pids}"
        )
        print("answers: " + ", ".join(f"{k} {v}" for k, v in sorted(result.replies.items())))
    return 1 if result.crashes else 0


#: benchmark name -> (its module, whose doc gives the help line; add arguments; run)
BENCHMARKS = {
    "migrate": (migrate, add_migrate_arguments, cmd_migrate),
    "sim": (sim, add_sim_arguments, cmd_sim),
    "round": (round_bench, add_round_arguments, cmd_round),
    "bridge": (bridge, add_bridge_arguments, cmd_bridge),
    "chaos": (chaos, add_chaos_arguments, cmd_chaos),
    "scale": (scale, add_scale_arguments, cmd_scale),
    "hostile": (hostile, bench_hostile.add_arguments, bench_hostile.cmd),
    "faults": (faults, bench_faults.add_arguments, bench_faults.cmd),
    "fuzz": (fuzz, add_fuzz_arguments, cmd_fuzz),
    "sim-fidelity": (fidelity, bench_fidelity.add_arguments, bench_fidelity.cmd),
    "vs-flower": (vs_flower, bench_vs_flower.add_arguments, bench_vs_flower.cmd),
}


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``bench`` and one sub-command per benchmark."""
    parser = subparsers.add_parser("bench", help="run a benchmark and print its figures")
    inner = parser.add_subparsers(dest="benchmark", metavar="BENCHMARK", required=True)
    for name, (module, add_arguments, func) in BENCHMARKS.items():
        sub = inner.add_parser(name, help=(module.__doc__ or "").strip().splitlines()[0])
        add_arguments(sub)
        _state_defaults(sub)
        sub.set_defaults(func=func)


def _state_defaults(parser: argparse.ArgumentParser) -> None:
    """Every option's help says its default (the CLI convention of every command)."""
    for action in parser._actions:
        shown = action.default not in (None, False, argparse.SUPPRESS)
        if shown and action.help and "default" not in action.help:
            action.help += " (default: %(default)s)"
