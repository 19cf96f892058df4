"""``dfrl demo``: the 5-robot dFRL demo on loopback (R1..R5, Q-learning, average, sync).

Five robot node processes, one itinerary agent; about a minute on a 2-core machine. Leaves
the plots, the CSVs and ``summary.md`` in ``results/demo`` and prints that path.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def cmd_demo(args: argparse.Namespace) -> int:
    from dfrl.experiments.cmd_run import apply_overrides, run_and_report
    from dfrl.experiments.config import ExperimentConfig, resolve_config
    from dfrl.robots.training import DEMO_ITERATIONS

    cfg = ExperimentConfig.load(resolve_config("demo"))
    if cfg.iterations != DEMO_ITERATIONS:
        cfg = cfg.replace(iterations=DEMO_ITERATIONS)
    cfg = apply_overrides(cfg, args)
    print(f"dfrl demo: {len(cfg.robots)} robots ({', '.join(r.arena.upper() for r in cfg.robots)}), "
          f"{cfg.method}, {cfg.iterations} iterations, a share every {cfg.respite} "
          f"({cfg.rounds} rounds), {cfg.mode.value} mode, seed {cfg.seed}", file=sys.stderr)
    return run_and_report(cfg, args.out, "dfrl demo", show_summary=True)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``demo`` subcommand."""
    from dfrl.experiments.cmd_run import add_override_arguments

    p = subparsers.add_parser("demo", help="the 5-robot dFRL demo on loopback (plots + summary "
                                           "in results/demo)")
    p.add_argument("--out", type=Path, default=Path("results/demo"), help="results folder")
    add_override_arguments(p)
    p.set_defaults(func=cmd_demo)
