"""``dfrl bench sim-fidelity``: its options and its output (registered in :mod:`.bench`).

The command layer of :mod:`dfrl.experiments.science.fidelity`: exit status 0 when every check
is within its stated tolerance in every arena, 1 when one is not, 2 for a bad option or arena.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from dfrl.arenas.spec import ArenaError, load_arena
from dfrl.experiments.science.fidelity.learning import LearningCheck
from dfrl.experiments.science.fidelity.report import FidelityOptions, render, run, write

_CHECKS = ("sensing", "transitions", "policies", "learning")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``dfrl bench sim-fidelity``, each help stating its default."""
    d, le = FidelityOptions(), LearningCheck()
    parser.add_argument(
        "--arenas", nargs="+", default=list(d.arenas), help="built-in arena names or arena files"
    )
    parser.add_argument(
        "--checks", nargs="+", choices=_CHECKS, default=list(_CHECKS), help="which checks to run"
    )
    parser.add_argument("--poses", type=int, default=d.poses, help="poses of the IR check")
    parser.add_argument(
        "--transitions",
        type=int,
        default=d.transitions,
        help="steps of the pybullet random walk replayed in batched",
    )
    parser.add_argument(
        "--policy-steps",
        type=int,
        default=d.policy_steps,
        help="steps of each fixed policy in each simulator",
    )
    parser.add_argument(
        "--n-seeds", type=int, default=le.seeds, help="paired seeds of the learning check"
    )
    parser.add_argument(
        "--tables", type=int, default=le.tables, help="tables learnt per seed in each simulator"
    )
    parser.add_argument(
        "--iterations", type=int, default=le.iterations, help="training iterations of each table"
    )
    parser.add_argument(
        "--eval-steps",
        type=int,
        default=le.eval_steps,
        help="pybullet evaluation steps of each table",
    )
    parser.add_argument(
        "--margin",
        type=float,
        default=le.margin,
        help="largest score difference the learning check accepts",
    )
    parser.add_argument(
        "--workers",
        type=int,
        default=d.workers,
        help="processes for the pybullet training and evaluation",
    )
    parser.add_argument("--seed", type=int, default=d.seed, help="seed of the poses and walks")
    parser.add_argument(
        "--out", type=Path, default=None, help="write fidelity.json and fidelity.md here"
    )
    parser.add_argument("--json", action="store_true", help="print the result as JSON")


def cmd(args: argparse.Namespace) -> int:
    """Run the checks; print the report (or JSON); 0 all within tolerance, 1 not, 2 bad input."""
    try:
        for arena in args.arenas:
            load_arena(arena)
        budget = LearningCheck(
            seeds=args.n_seeds,
            tables=args.tables,
            iterations=args.iterations,
            eval_steps=args.eval_steps,
            margin=args.margin,
        )
        budget.check()
        if min(args.poses, args.transitions, args.workers) < 1:
            raise ValueError("--poses, --transitions and --workers must be >= 1")
    except (ArenaError, ValueError) as exc:
        print(f"dfrl bench sim-fidelity: error: {exc}", file=sys.stderr)
        return 2
    opts = FidelityOptions(
        arenas=tuple(args.arenas),
        poses=args.poses,
        transitions=args.transitions,
        policy_steps=args.policy_steps,
        learning=budget,
        seed=args.seed,
        workers=args.workers,
        checks=tuple(args.checks),
    )
    try:
        result = run(
            opts, progress=lambda s: print(f"[sim-fidelity] {s}", file=sys.stderr, flush=True)
        )
    except ValueError as exc:
        print(f"dfrl bench sim-fidelity: error: {exc}", file=sys.stderr)
        return 2
    if args.out is not None:
        write(result, args.out)
    print(json.dumps(result) if args.json else render(result), end="" if not args.json else "\n")
    return 0 if result["holds"] else 1
