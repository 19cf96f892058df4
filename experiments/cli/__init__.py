"""The ``dfrl`` command line: parses, calls library functions, prints, chooses exit codes.

One module per command group, each with ``register(subparsers)``: it adds its parsers and
sets ``func`` (called with the parsed namespace, returning an exit code). Every module is
imported when the parser is built; a module that fails to import is an error, not a missing
command. ``dfrl node`` builds only its own parser: it imports neither the simulation nor the
learners (a platform node needs none of them).
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from dfrl import __version__

#: Modules (of this package) that add subcommands, in the order of ``dfrl --help``.
COMMAND_MODULES = (
    "node",
    "federated",
    "running",
    "history",
    "bench",
    "standalone",
    "transfer",
    "studies",
    "hetero",
    "robot",
    "view",
    "secret",
    "certs",
)


def build_parser(only: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """Build the top-level parser with every subcommand (or those of the modules ``only``)."""
    parser = argparse.ArgumentParser(
        prog="dfrl",
        description="Decentralized federated RL test bed driven by mobile agents.",
    )
    parser.add_argument("--version", action="version", version=f"dfrl {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in only or COMMAND_MODULES:
        importlib.import_module(f"{__name__}.{name}").register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``dfrl`` console script."""
    args_in = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser(["node"] if args_in[:1] == ["node"] else None)
    args = parser.parse_args(args_in)
    func = getattr(args, "func", None)
    if func is None:
        parser.print_help()
        return 2
    return int(func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
