"""``dfrl secret``: print a strong platform token (256 random bits), or write it to a new
token file of mode 0600 (``--out FILE``, for ``--token-file``)."""

from __future__ import annotations

import argparse
import secrets
import sys
from pathlib import Path

from dfrl.experiments.tokens import new_secret, write_secret_file

__all__ = ["new_integer_secret", "register"]


def new_integer_secret() -> int:
    """A token that is an integer of 129 bits (at least 2**128), for configs and tools that
    take Tartarus-style integer tokens (experiment configs do)."""
    return 2**128 + secrets.randbelow(2**128)


def secret_main(args: argparse.Namespace) -> int:
    token = new_integer_secret() if args.integer else new_secret()
    if args.out is None:
        print(token)
        return 0
    if args.out.exists():
        print(f"dfrl secret: {args.out} exists; not replacing it", file=sys.stderr)
        return 2
    write_secret_file(args.out, [token])
    print(
        f"dfrl secret: a new token in {args.out} (mode 600): give it to dfrl robot, dfrl "
        "node and dfrl run with --token-file",
        file=sys.stderr,
    )
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "secret",
        help="print a strong platform token",
        description="Print a token with 256 bits of entropy, for the token file (--token-file) "
        "or DFRL_TOKEN of nodes reachable "
        "from the network (nodes off loopback refuse tokens under 128 bits "
        "without TLS unless told --insecure).",
    )
    p.add_argument(
        "--integer",
        action="store_true",
        help="print an integer of 129 random bits instead (experiment configs take integer tokens)",
    )
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        metavar="FILE",
        help="write it to FILE, created with mode 600, instead of printing it "
        "(the token file of --token-file; FILE must not exist)",
    )
    p.set_defaults(func=secret_main)
