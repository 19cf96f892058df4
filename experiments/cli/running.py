"""``dfrl inject``, ``dfrl join`` and ``dfrl collect``: acting on a run from its results folder
(while it runs, or after its driver stopped), through the platform; ``dfrl run`` and ``dfrl
demo`` are in :mod:`.federated`.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from dfrl.experiments.cli.federated import print_results
from dfrl.experiments.cli.tensorboard_option import add_tensorboard_argument, write_run_tensorboard
from dfrl.experiments.driver.config import ConfigError
from dfrl.experiments.errors import ExperimentError


def driver_tls_arg(args: argparse.Namespace, prog: str) -> tuple[Path | None, int]:
    """``--tls DIR`` of ``dfrl inject``/``join`` checked: (the folder or None, 0), or
    (None, 2) after saying what is wrong with it."""
    from dfrl.experiments.tls_folder import CertError, check_node_dir

    if args.tls is None:
        return None, 0
    try:
        return check_node_dir(args.tls).resolve(), 0
    except CertError as exc:
        print(f"{prog}: --tls: {exc}; nothing was sent", file=sys.stderr)
        return None, 2


def add_driver_tls_argument(p: argparse.ArgumentParser) -> None:
    """``--tls DIR`` of ``dfrl inject``/``join``: the driver's certificate folder here."""
    p.add_argument(
        "--tls",
        type=Path,
        default=None,
        metavar="DIR",
        help="the driver's node TLS folder on this host (ca.crt, node.crt, "
        "node.key), instead of the one nodes.json records (default: that "
        "one; none for a plaintext run)",
    )


def cmd_inject(args: argparse.Namespace) -> int:
    from dfrl.experiments.driver.launcher import inject_method

    tls, rc = driver_tls_arg(args, "dfrl inject")
    if rc:
        return rc
    try:
        told = inject_method(
            args.results_dir, args.program, args.method, args.agent, wait_s=args.wait, tls=tls
        )
    except ExperimentError as exc:
        print(f"dfrl inject: {exc}", file=sys.stderr)
        return 1
    applied = [a for a, st in told.items() if st == "applied"]
    pending = [a for a, st in told.items() if st != "applied"]
    if applied:
        print(
            f"method {args.method} applied by {', '.join(applied)} (acknowledged in the round log)"
        )
    if pending:
        print(
            f"method {args.method} sent to {', '.join(pending)}, not acknowledged "
            f"{'yet (--wait 0)' if args.wait <= 0 else f'within {args.wait:g} s'}",
            file=sys.stderr,
        )
        return 3
    return 0


def cmd_join(args: argparse.Namespace) -> int:
    from dfrl.experiments.driver.launcher import join_robot

    tls, rc = driver_tls_arg(args, "dfrl join")
    if rc:
        return rc
    try:
        info = join_robot(
            args.results_dir,
            args.robot,
            args.arena,
            args.algo,
            iterations=args.iterations,
            seed=args.seed,
            node=args.robot_host,
            tls=tls,
        )
    except ConfigError as exc:
        n = len(exc.problems)
        print(
            f"dfrl join: the join request has {n} problem{'s' if n != 1 else ''}; nothing "
            "was started",
            file=sys.stderr,
        )
        for line in exc.problems:
            print(f"  {line}", file=sys.stderr)
        return 2
    except (ExperimentError, ValueError) as exc:
        print(f"dfrl join: {exc}", file=sys.stderr)
        return 1
    where = f"robot host {info['robot_host']}" if info.get("robot_host") else f"pid {info['pid']}"
    print(
        f"robot {args.robot} runs at {info['host']}:{info['port']} ({where}); "
        f"the agent includes it from its next round"
    )
    return 0


def cmd_collect(args: argparse.Namespace) -> int:
    """``dfrl collect``: 0 complete, 1 not, 2 not a results folder."""
    from dfrl.experiments.driver.collect import NotAResultsFolder, collect

    tls, rc = driver_tls_arg(args, "dfrl collect")
    if rc:
        return rc
    try:
        results = collect(args.results_dir, wait_s=args.wait, tls=tls)
    except NotAResultsFolder as exc:
        print(f"dfrl collect: {exc}", file=sys.stderr)
        return 2
    except ExperimentError as exc:
        print(f"dfrl collect: {exc}", file=sys.stderr)
        return 1
    print_results(results)
    write_run_tensorboard(results, args, "dfrl collect")
    return 0 if results.ok else 1


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``inject``, ``join`` and ``collect``."""
    p = subparsers.add_parser(
        "inject",
        help="load an aggregation method into a running "
        "experiment and wait until the agent applied it "
        "(exit 1 if it refused, 3 if it did not answer)",
    )
    p.add_argument("results_dir", type=Path, help="results folder of the running experiment")
    p.add_argument(
        "--program",
        type=Path,
        required=True,
        help="Prolog file defining dfrl_aggregation:aggregate_init/step/final for "
        "METHOD (required)",
    )
    p.add_argument("--method", required=True, help="method name (required)")
    p.add_argument("--agent", default=None, help="only this agent (default: every agent)")
    p.add_argument(
        "--wait",
        type=float,
        default=120.0,
        metavar="S",
        help="seconds to wait for the agent's acknowledgement (default: %(default)s; "
        "0: do not wait)",
    )
    add_driver_tls_argument(p)
    p.set_defaults(func=cmd_inject)

    p = subparsers.add_parser(
        "join",
        help="start a new robot process and add it to a running experiment's agent (next round)",
    )
    p.add_argument("results_dir", type=Path, help="results folder of the running experiment")
    p.add_argument("--robot", required=True, help="new robot id, e.g. r6 (required)")
    p.add_argument("--arena", required=True, help="arena name or file (required)")
    p.add_argument("--algo", default="qlearning", help="learner (default: %(default)s)")
    p.add_argument(
        "--iterations", type=int, default=None, help="iterations (default: the experiment's)"
    )
    p.add_argument(
        "--seed",
        type=int,
        default=None,
        help="robot seed (default: the experiment seed + its position)",
    )
    p.add_argument(
        "--robot-host",
        "--node",
        dest="robot_host",
        default=None,
        metavar="HOST:PORT",
        help="a running `dfrl robot` service to run the robot on (--node: its old "
        "name; default: a new robot process on the launcher's host)",
    )
    add_driver_tls_argument(p)
    p.set_defaults(func=cmd_join)

    p = subparsers.add_parser(
        "collect",
        help="write the end-of-run files (rounds.csv, "
        "metrics.csv, tables/, summary.md) of a run whose "
        "driver stopped, fetching what its robot hosts "
        "hold; exit 1 unless the federation completed, "
        "2: no results folder",
    )
    p.add_argument("results_dir", type=Path, help="results folder of the run")
    p.add_argument(
        "--wait",
        type=float,
        default=30.0,
        metavar="S",
        help="seconds robots still running the run get to end (default: %(default)s)",
    )
    add_driver_tls_argument(p)
    add_tensorboard_argument(p)
    p.set_defaults(func=cmd_collect)
