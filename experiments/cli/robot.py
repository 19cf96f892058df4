"""``dfrl robot``: a long-lived robot process that experiments configure over the platform."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from dfrl.experiments.cli.node import (
    add_bound_arguments,
    add_token_arguments,
    add_trust_argument,
    bounds_of_args,
    check_trust_names,
    tokens_of_args,
)
from dfrl.experiments.cli.ports import port_in_use_text
from dfrl.experiments.robot_host.process import NodeStartError
from dfrl.experiments.robot_host.service import RobotService
from dfrl.experiments.tls_folder import CertError, check_node_dir
from dfrl.experiments.tokens import TOKEN_ENV, TokenError
from dfrl.pybridge.errors import BridgeError


def _run(args: argparse.Namespace) -> int:
    if not 0 <= args.port <= 65535:
        print(f"dfrl robot: port {args.port} is outside 0..65535", file=sys.stderr)
        return 2
    if args.trust and not args.tls:
        print("dfrl robot: --trust needs --tls (trust is by TLS certificate name)", file=sys.stderr)
        return 2
    try:
        check_trust_names(args.trust)
        tls = check_node_dir(args.tls) if args.tls else None
    except ValueError as exc:
        print(f"dfrl robot: {exc}", file=sys.stderr)
        return 2
    except CertError as exc:
        print(f"dfrl robot: --tls: {exc}", file=sys.stderr)
        return 2
    try:
        tokens = tokens_of_args(args, "dfrl robot")
    except TokenError as exc:
        print(f"dfrl robot: {exc}", file=sys.stderr)
        return 2
    if not tokens:
        print(
            f"dfrl robot: no token: give the experiment's token in {TOKEN_ENV} or "
            "--token-file FILE ('dfrl secret' prints a strong one)",
            file=sys.stderr,
        )
        return 2
    service = RobotService(
        args.host,
        args.port,
        tokens,
        args.advertise,
        Path(args.workdir),
        insecure=args.insecure,
        tls=tls,
        trust=tuple(args.trust),
        bounds=bounds_of_args(args),
    )
    service.install_signals()
    try:
        service.start()
    except NodeStartError as exc:
        if exc.address_in_use:
            print(
                "dfrl robot: "
                + port_in_use_text(args.host, args.port, "another dfrl robot or node", "--port"),
                file=sys.stderr,
            )
            service.close()
            return 1
        hint = ""
        if exc.weak_token and args.host not in ("127.0.0.1", "localhost", "::1"):
            hint = (
                f"; --host {args.host} serves every interface, "
                "--host 127.0.0.1 serves this host only and accepts a short token"
            )
        print(f"dfrl robot: cannot start on {args.host}:{args.port}: {exc}{hint}", file=sys.stderr)
        service.close()
        return 1
    except (BridgeError, OSError) as exc:
        print(f"dfrl robot: cannot start on {args.host}:{args.port}: {exc}", file=sys.stderr)
        service.close()
        return 1
    try:
        return service.serve_forever()
    finally:
        service.close()


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``robot`` subcommand."""
    p = subparsers.add_parser(
        "robot",
        help="run a robot process that experiments configure over the platform",
        description="Start a long-lived robot process: an embedded platform node on HOST:PORT "
        "that prints 'dfrl robot listening on A:P' and waits for experiments "
        "(dfrl_robot requests from peers that prove its token, read from "
        "DFRL_TOKEN or --token-file). SIGTERM or Ctrl-C "
        "stops it cleanly.",
    )
    p.add_argument(
        "--host", default="0.0.0.0", help="address to bind (default 0.0.0.0: every interface)"
    )
    p.add_argument("--port", type=int, default=7001, help="port to bind (default 7001)")
    add_token_arguments(
        p,
        "the platform tokens peers and agents must prove (the experiment's token; one is required)",
    )
    p.add_argument(
        "--advertise",
        default=None,
        metavar="HOST",
        help="host name or address others reach this robot at "
        "(default: the bound host; 0.0.0.0 becomes this host's name)",
    )
    p.add_argument(
        "--workdir",
        default="dfrl-robot",
        metavar="DIR",
        help="experiments' files go to DIR/<experiment>/ (default ./dfrl-robot)",
    )
    p.add_argument(
        "--insecure",
        action="store_true",
        help="accept a token under 128 bits on an address other than loopback "
        "(default: refused; see dfrl secret)",
    )
    p.add_argument(
        "--tls",
        default=None,
        metavar="DIR",
        help="mutual TLS with the node certificate in DIR (ca.crt, node.crt, "
        "node.key from 'dfrl certs node'); any token is then accepted off "
        "loopback (default: plaintext)",
    )
    add_trust_argument(p)
    add_bound_arguments(p)
    p.set_defaults(func=_run)
