"""``dfrl hetero``: a dqn robot and a Q-learning robot in one grid federation vs each alone.

Thin CLI over :func:`dfrl.experiments.science.studies.hetero.run`.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from dfrl.experiments.cli.seeds import add_seed_arguments, chosen_seeds
from dfrl.experiments.cli.sim_option import add_sim_argument, chosen_sim


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``hetero``."""
    p = subparsers.add_parser(
        "hetero",
        help="heterogeneous federation: does a dqn robot gain from a tabular peer, and the "
        "reverse (paired by seed)",
        description="Per seed: a dqn robot alone, a Q-learning robot alone, both in one grid "
        "federation (Q-values on the state grid; the dqn absorbs the aggregate by "
        "distillation), and the Q-learning robot with a Q-learning peer (control). "
        "Greedy score and collisions per 1,000 steps at --eval-at, differences "
        "paired by seed with 95% t intervals.",
    )
    add_seed_arguments(p, 5)
    p.add_argument("--arena", default="r1", help="arena of every robot (default: %(default)s)")
    p.add_argument(
        "--iterations", type=int, default=8000, help="iterations per robot (default: %(default)s)"
    )
    p.add_argument(
        "--respite",
        type=int,
        default=500,
        help="iterations between two shares (default: %(default)s)",
    )
    p.add_argument(
        "--method",
        default="average",
        help="aggregation: average, max, visit_average, max_visited (default: %(default)s)",
    )
    p.add_argument(
        "--eval-at",
        type=int,
        nargs="+",
        default=[2000, 4000, 8000],
        metavar="IT",
        help="iterations at which every robot's greedy policy is measured "
        "(default: 2000 4000 8000)",
    )
    p.add_argument(
        "--eval-steps",
        type=int,
        default=1000,
        help="greedy steps per evaluation (default: %(default)s)",
    )
    p.add_argument("--jobs", type=int, default=2, help="worker processes (default: %(default)s)")
    add_sim_argument(p, "; batched runs the Q-learning robots batched, the dqn on pybullet")
    p.add_argument(
        "--out", type=Path, default=None, help="write options.json, rows.csv, results.json here"
    )
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    p.set_defaults(func=cmd_hetero)


def _fmt(entry: dict) -> str:
    half = entry["half"]
    mean = f"{entry['mean']:+.3f}"
    return mean if math.isnan(half) else f"{mean} ± {half:.3f}"


def cmd_hetero(args: argparse.Namespace) -> int:
    from dfrl.experiments.science.studies.hetero import HeteroOptions, run

    try:
        options = HeteroOptions(
            seeds=chosen_seeds(args),
            arena=args.arena,
            iterations=args.iterations,
            respite=args.respite,
            method=args.method,
            eval_at=tuple(args.eval_at),
            eval_steps=args.eval_steps,
            jobs=args.jobs,
            sim=chosen_sim(args),
        )
        results = run(options, args.out)
    except ValueError as exc:
        print(f"dfrl hetero: {exc}", file=sys.stderr)
        return 2
    if args.json:
        print(json.dumps(results.to_dict()))
        return 0
    print(
        f"hetero: {len(options.seeds)} seeds, {options.iterations} iterations in "
        f"{options.arena}, share every {options.respite} ({options.method}), "
        f"{results.seconds:.0f} s; simulator: "
        f"{', '.join(f'{a} {s}' for a, s in results.simulators.items())}"
    )
    print(
        "robot  run      vs baseline  iteration  score (run, base, difference)      "
        "collisions/1000 (difference)"
    )
    for c in results.comparisons:
        run_, base = c["run"], c["baseline"]
        print(
            f"{c['role']:<6} {run_:<8} {base:<12} {c['iteration']:>9}  "
            f"{c[f'score_{run_}']:.3f} {c[f'score_{base}']:.3f} {_fmt(c['score']):<18} "
            f"{_fmt(c['collisions'])}"
        )
    r = results.residuals
    print(
        f"dqn distillation residual (RMS per share): mean {r['mean']:.4f}, max {r['max']:.4f} "
        f"over {r['shares']} shares"
    )
    return 0
