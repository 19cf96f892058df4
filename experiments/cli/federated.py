"""Federated experiments: ``dfrl demo``, ``dfrl run CONFIG``, ``dfrl inject``, ``dfrl join``
and ``dfrl paper``.

``dfrl demo`` is the 5-robot dFRL demo on loopback (R1..R5, Q-learning, average, sync): five
robot node processes, one itinerary agent, about a minute on a 2-core machine; it leaves the
plots, the CSVs and ``summary.md`` in ``results/demo`` and prints that path.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from dfrl.experiments.config import ExperimentConfig, Mode, resolve_config
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.results.summary import Results


def add_override_arguments(p: argparse.ArgumentParser) -> None:
    """Flags that override fields of an experiment config."""
    g = p.add_argument_group("overrides")
    g.add_argument("--iterations", type=int, default=None, help="iterations per robot")
    g.add_argument("--respite", type=int, default=None, help="iterations between two shares")
    g.add_argument("--seed", type=int, default=None)
    g.add_argument("--mode", choices=[m.value for m in Mode], default=None,
                   help="async: robots flat out; sync: robots wait for the agent at each respite")
    g.add_argument("--rtf", type=float, default=None,
                   help="real-time factor (1.0 = one iteration per 64 ms; 0 = flat out)")
    g.add_argument("--method", default=None, help="aggregation method of every agent")
    g.add_argument("--timeout", type=float, default=None, help="experiment time limit (s)")


def apply_overrides(cfg: ExperimentConfig, args: argparse.Namespace) -> ExperimentConfig:
    """``cfg`` with the override flags that were given."""
    changes = {}
    for name, key in (("iterations", "iterations"), ("respite", "respite"), ("seed", "seed"),
                      ("mode", "mode"), ("timeout", "timeout_s")):
        v = getattr(args, name, None)
        if v is not None:
            changes[key] = v
    if getattr(args, "rtf", None) is not None:
        changes["rtf"] = args.rtf or None
    if getattr(args, "method", None) is not None:
        changes["method"] = args.method
        changes["methods"] = {}
    return cfg.replace(**changes) if changes else cfg


def print_results(results: Results) -> None:
    """Rounds, crashes on stderr; the results folder on stdout."""
    print(f"{len(results.rounds)} rounds, {results.equal_rounds} with every robot holding the same table "
          f"after the share; wall time {results.wall_time_s:.1f} s", file=sys.stderr)
    if results.crashed:
        print(f"crashed robots: {results.crashed}", file=sys.stderr)
    if results.faults is not None:
        for line in results.faults.lines():
            print(line, file=sys.stderr)
        if not results.complete:
            print("the federation did NOT complete (see summary.md)", file=sys.stderr)
    print(results.output_dir)


def run_and_report(cfg: ExperimentConfig, out: Path, prog: str, show_summary: bool = False) -> int:
    """Run experiment ``cfg`` into ``out`` and report it; the command's exit code."""
    from dfrl.experiments.launcher import run

    try:
        results = run(cfg, out)
    except ExperimentError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"{prog}: interrupted; partial results in {out}", file=sys.stderr)
        return 130
    summary = results.output_dir / "summary.md"
    if show_summary and summary.is_file():
        print(summary.read_text(encoding="utf-8"), file=sys.stderr)
    print_results(results)
    return 0 if results.ok else 1


def cmd_demo(args: argparse.Namespace) -> int:
    """``dfrl demo``: the shipped ``demo`` config at the demo budget."""
    from dfrl.robots.training import DEMO_ITERATIONS

    cfg = ExperimentConfig.load(resolve_config("demo"))
    if cfg.iterations != DEMO_ITERATIONS:
        cfg = cfg.replace(iterations=DEMO_ITERATIONS)
    cfg = apply_overrides(cfg, args)
    print(f"dfrl demo: {len(cfg.robots)} robots ({', '.join(r.arena.upper() for r in cfg.robots)}), "
          f"{cfg.method}, {cfg.iterations} iterations, a share every {cfg.respite} "
          f"({cfg.rounds} rounds), {cfg.mode.value} mode, seed {cfg.seed}", file=sys.stderr)
    return run_and_report(cfg, args.out, "dfrl demo", show_summary=True)


def cmd_run(args: argparse.Namespace) -> int:
    try:
        cfg = apply_overrides(ExperimentConfig.load(resolve_config(args.config)), args)
    except (FileNotFoundError, ValueError) as exc:
        print(f"dfrl run: {exc}", file=sys.stderr)
        return 2
    return run_and_report(cfg, args.out or Path("results") / cfg.name, "dfrl run")


def cmd_inject(args: argparse.Namespace) -> int:
    from dfrl.experiments.launcher import inject_method

    try:
        told = inject_method(args.results_dir, args.program, args.method, args.agent)
    except ExperimentError as exc:
        print(f"dfrl inject: {exc}", file=sys.stderr)
        return 1
    print(f"method {args.method} loaded; agents {', '.join(told)} use it from their next round")
    return 0


def cmd_join(args: argparse.Namespace) -> int:
    from dfrl.experiments.launcher import join_robot

    try:
        info = join_robot(args.results_dir, args.robot, args.arena, args.algo,
                          iterations=args.iterations, seed=args.seed, node=args.node)
    except (ExperimentError, ValueError) as exc:
        print(f"dfrl join: {exc}", file=sys.stderr)
        return 1
    where = f"robot node {info['node']}" if info.get("node") else f"pid {info['pid']}"
    print(f"robot {args.robot} runs at {info['host']}:{info['port']} ({where}); "
          f"the agent includes it from its next round")
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``demo``, ``run``, ``inject`` and ``join`` (``paper`` is in :mod:`.studies`)."""
    p = subparsers.add_parser("demo", help="the 5-robot dFRL demo on loopback (plots + summary "
                                           "in results/demo)")
    p.add_argument("--out", type=Path, default=Path("results/demo"), help="results folder")
    add_override_arguments(p)
    p.set_defaults(func=cmd_demo)

    p = subparsers.add_parser("run", help="run a federated experiment (robot processes + agent); "
                                          "exit 1 unless the federation completed")
    p.add_argument("config", help="experiment config: a JSON file or a name in experiments/configs")
    p.add_argument("--out", type=Path, default=None, help="results folder (default results/NAME)")
    add_override_arguments(p)
    p.set_defaults(func=cmd_run)

    p = subparsers.add_parser("inject", help="load an aggregation method into a running "
                                             "experiment; the agent uses it from its next round")
    p.add_argument("results_dir", type=Path, help="results folder of the running experiment")
    p.add_argument("--program", type=Path, required=True,
                   help="Prolog file defining dfrl_agent:aggregate_init/step/final for METHOD")
    p.add_argument("--method", required=True, help="method name")
    p.add_argument("--agent", default=None, help="only this agent (default: every agent)")
    p.set_defaults(func=cmd_inject)

    p = subparsers.add_parser("join", help="start a new robot node and add it to a running "
                                           "experiment's agent (next round)")
    p.add_argument("results_dir", type=Path)
    p.add_argument("--robot", required=True, help="new robot id, e.g. r6")
    p.add_argument("--arena", required=True)
    p.add_argument("--algo", default="qlearning")
    p.add_argument("--iterations", type=int, default=None,
                   help="iterations (default: the experiment's)")
    p.add_argument("--seed", type=int, default=None)
    p.add_argument("--node", default=None, metavar="HOST:PORT",
                   help="a running `dfrl robot` to run the robot on (default: a new robot "
                        "process on the launcher's host)")
    p.set_defaults(func=cmd_join)
