"""``dfrl demo``: the 5-robot dFRL demo on loopback (R1..R5, Q-learning, average, sync).

Five robot node processes, one itinerary agent; about a minute on a 2-core machine. Leaves
the plots, the CSVs and ``summary.md`` in ``results/demo`` and prints that path.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path


def cmd_demo(args: argparse.Namespace) -> int:
    from experiments.cmd_run import apply_overrides, print_results, resolve_config
    from experiments.federation import ExperimentConfig, ExperimentError, run
    from robots.training import DEMO_ITERATIONS

    cfg = ExperimentConfig.load(resolve_config("demo"))
    if cfg.iterations != DEMO_ITERATIONS:
        cfg = cfg.replace(iterations=DEMO_ITERATIONS)
    cfg = apply_overrides(cfg, args)
    print(f"dfrl demo: {len(cfg.robots)} robots ({', '.join(r.arena.upper() for r in cfg.robots)}), "
          f"{cfg.method}, {cfg.iterations} iterations, a share every {cfg.respite} "
          f"({cfg.rounds} rounds), {cfg.mode.value} mode, seed {cfg.seed}", file=sys.stderr)
    try:
        results = run(cfg, args.out)
    except ExperimentError as exc:
        print(f"dfrl demo: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"dfrl demo: interrupted; partial results in {args.out}", file=sys.stderr)
        return 130
    summary = results.output_dir / "summary.md"
    if summary.is_file():
        print(summary.read_text(encoding="utf-8"), file=sys.stderr)
    print_results(results)
    return 0 if results.ok else 1


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``demo`` subcommand."""
    from experiments.cmd_run import add_override_arguments

    p = subparsers.add_parser("demo", help="the 5-robot dFRL demo on loopback (plots + summary "
                                           "in results/demo)")
    p.add_argument("--out", type=Path, default=Path("results/demo"), help="results folder")
    add_override_arguments(p)
    p.set_defaults(func=cmd_demo)
