"""The ``dfrl`` command line.

Each subcommand lives in its own module, which exposes ``register(subparsers)``: it adds
its parser and sets ``func`` (called with the parsed namespace, returning an exit code).
The modules are imported lazily by name so that a broken optional part (e.g. plotting)
does not stop the others from working.
"""
from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

#: Modules that add subcommands, in the order they appear in ``dfrl --help``.
COMMAND_MODULES: tuple[str, ...] = (
    "dfrl.experiments.cmd_node",
    "dfrl.experiments.cmd_demo",
    "dfrl.experiments.cmd_run",
    "dfrl.experiments.cmd_bench",
    "dfrl.experiments.cmd_robots",
    "dfrl.experiments.cmd_transfer",
)


def build_parser() -> argparse.ArgumentParser:
    """Build the top-level parser with every registered subcommand."""
    parser = argparse.ArgumentParser(
        prog="dfrl",
        description="Decentralized federated RL test bed driven by mobile agents.",
    )
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if exc.name == name:
                continue  # a part not built yet
            raise
        module.register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``dfrl`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    func = getattr(args, "func", None)
    if func is None:
        parser.print_help()
        return 2
    return int(func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
