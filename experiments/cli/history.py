"""``dfrl check-history``: check the table writes a run's robots recorded
(:mod:`dfrl.experiments.driver.results.history`) and say whether they kept the rules."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

__all__ = ["cmd_check_history", "register"]


def cmd_check_history(args: argparse.Namespace) -> int:
    """``dfrl check-history``: 0 no violation, 1 violations, 2 no readable history (or one
    without a single agent write)."""
    from dfrl.experiments.driver.results.history import HistoryInputError, check_history

    try:
        verdict = check_history(args.results_dir)
    except HistoryInputError as exc:
        print(f"dfrl check-history: {exc}", file=sys.stderr)
        return 2
    if verdict.writes == 0:  # nothing checked is no verdict, never an "ok"
        print(
            f"dfrl check-history: {args.results_dir}: its shares files hold no agent's "
            "write: nothing to check",
            file=sys.stderr,
        )
        return 2
    if args.json:
        print(json.dumps(verdict.to_json(), indent=2))
    else:
        print(verdict.text(shown=len(verdict.violations)))
    return 0 if verdict.ok else 1


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``check-history``."""
    p = subparsers.add_parser(
        "check-history",
        help="check the table writes a run's robots recorded (shares_*.csv): no doubled "
        "write, no epoch regressed, no stale epoch, no split round (exit 1: violations, "
        "2: no readable history)",
    )
    p.add_argument("results_dir", type=Path, help="results folder of the run")
    p.add_argument(
        "--json",
        action="store_true",
        help="print the verdict as JSON (ok, counts, every violation)",
    )
    p.set_defaults(func=cmd_check_history)
