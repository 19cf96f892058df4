"""``dfrl certs``: a project CA and node certificates for mutual TLS between nodes."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from dfrl.experiments.tls_folder import CertError
from dfrl.experiments.tools.certs import init_ca, make_node


def _init(args: argparse.Namespace) -> int:
    try:
        cert = init_ca(args.dir, force=args.force)
    except CertError as exc:
        print(f"dfrl certs init: {exc}", file=sys.stderr)
        return 2
    print(f"CA certificate {cert} (key {cert.with_name('ca.key')}, mode 0600)")
    return 0


def _node(args: argparse.Namespace) -> int:
    try:
        node = make_node(args.name, args.dir, out=args.out, force=args.force)
    except CertError as exc:
        print(f"dfrl certs node: {exc}", file=sys.stderr)
        return 2
    print(f"node {node.name}: {node.directory} (use it as --tls {node.directory})")
    return 0


def _usage(parser: argparse.ArgumentParser) -> int:
    parser.print_help(sys.stderr)
    return 2


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``certs`` subcommand group (``init``, ``node``)."""
    p = subparsers.add_parser(
        "certs", help="make a project CA and node certificates (mutual TLS)",
        description="Certificates for --tls: a project CA signs one certificate per node; a "
                    "TLS node accepts only peers whose certificate that CA signed.")
    p.set_defaults(func=lambda _a: _usage(p))
    sub = p.add_subparsers(dest="certs_command", metavar="ACTION")
    i = sub.add_parser("init", help="make a project CA: DIR/ca.crt and DIR/ca.key (mode 0600)")
    i.add_argument("dir", metavar="DIR", help="folder for the CA (created if missing)")
    i.add_argument("--force", action="store_true",
                   help="replace a CA already in DIR (default: refuse)")
    i.set_defaults(func=_init)
    n = sub.add_parser("node", help="make a node certificate signed by the CA in DIR")
    n.add_argument("name", metavar="NAME",
                   help="the node's name: the certificate's CN and subjectAltName DNS entry")
    n.add_argument("dir", metavar="DIR", help="folder of the CA (from 'dfrl certs init')")
    n.add_argument("--out", metavar="NODE_DIR", type=Path, default=None,
                   help="where to write ca.crt, node.crt, node.key (default: DIR/NAME)")
    n.add_argument("--force", action="store_true",
                   help="replace a certificate already in NODE_DIR (default: refuse)")
    n.set_defaults(func=_node)
