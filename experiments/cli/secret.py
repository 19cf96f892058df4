"""``dfrl secret``: print a strong platform token (256 random bits)."""
from __future__ import annotations

import argparse
import secrets

PREFIX = "dfrl_"


def new_secret() -> str:
    """A token of 256 random bits: ``dfrl_`` and 64 hex digits (an atom Prolog writes unquoted,
    so its canonical text, the key of the token proof, is the token itself).

    The prefix keeps ``dfrl node``/``dfrl robot`` from reading it as a number (they read
    digit-only tokens as integers, as Tartarus does).
    """
    return PREFIX + secrets.token_hex(32)


def new_integer_secret() -> int:
    """A token that is an integer of 129 bits (at least 2**128), for configs and tools that
    take Tartarus-style integer tokens (experiment configs do)."""
    return 2**128 + secrets.randbelow(2**128)


def secret_main(args: argparse.Namespace) -> int:
    print(new_integer_secret() if args.integer else new_secret())
    return 0


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "secret", help="print a strong platform token",
        description="Print a token with 256 bits of entropy, for --token on nodes reachable "
                    "from the network (nodes off loopback refuse tokens under 128 bits "
                    "without TLS unless told --insecure).")
    p.add_argument("--integer", action="store_true",
                   help="print an integer of 129 random bits instead (experiment configs take "
                        "integer tokens)")
    p.set_defaults(func=secret_main)
