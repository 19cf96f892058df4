"""The ``dfrl`` command line: parses, calls library functions, prints, chooses exit codes.

One module per command group, each with ``register(subparsers)``: it adds its parsers and
sets ``func`` (called with the parsed namespace, returning an exit code). Every module is
imported up front; a module that fails to import is an error, not a missing command.
"""
from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from dfrl import __version__
from dfrl.experiments.cli import bench, federated, node, robot, robots, studies, transfer

#: Modules that add subcommands, in the order they appear in ``dfrl --help``.
COMMAND_MODULES = (node, federated, bench, robots, transfer, studies, robot)


def build_parser() -> argparse.ArgumentParser:
    """Build the top-level parser with every subcommand."""
    parser = argparse.ArgumentParser(
        prog="dfrl",
        description="Decentralized federated RL test bed driven by mobile agents.",
    )
    parser.add_argument("--version", action="version", version=f"dfrl {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module in COMMAND_MODULES:
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
