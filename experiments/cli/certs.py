"""``dfrl certs``: a project CA and node certificates for mutual TLS between nodes, and the
certificates of the Dask cluster's members (``dfrl certs cluster``)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from dfrl.experiments.tls_folder import CertError
from dfrl.experiments.tools.certs import init_ca, make_cluster_member, make_node


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


def _cluster(args: argparse.Namespace) -> int:
    try:
        member = make_cluster_member(args.name, args.dir, out=args.out, force=args.force)
    except CertError as exc:
        print(f"dfrl certs cluster: {exc}", file=sys.stderr)
        return 2
    d = member.directory
    print(
        f"cluster member {member.name}: {d} (dask scheduler/worker: --tls-ca-file "
        f"{d}/ca.crt --tls-cert {d}/cluster.crt --tls-key {d}/cluster.key; the driver: "
        f"--cluster tls://... --cluster-tls {d})"
    )
    return 0


def _usage(parser: argparse.ArgumentParser) -> int:
    parser.print_help(sys.stderr)
    return 2


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``certs`` subcommand group (``init``, ``node``, ``cluster``)."""
    p = subparsers.add_parser(
        "certs",
        help="make a project CA and node certificates (mutual TLS)",
        description="Certificates for --tls: a project CA signs one certificate per node; a "
        "TLS node accepts only peers whose certificate that CA signed.",
    )
    p.set_defaults(func=lambda _a: _usage(p))
    sub = p.add_subparsers(dest="certs_command", metavar="ACTION")
    i = sub.add_parser("init", help="make a project CA: DIR/ca.crt and DIR/ca.key (mode 0600)")
    i.add_argument("dir", metavar="DIR", help="folder for the CA (created if missing)")
    i.add_argument(
        "--force", action="store_true", help="replace a CA already in DIR (default: refuse)"
    )
    i.set_defaults(func=_init)
    n = sub.add_parser("node", help="make a node certificate signed by the CA in DIR")
    n.add_argument(
        "name",
        metavar="NAME",
        help="the node's name: the certificate's CN and subjectAltName DNS entry",
    )
    n.add_argument("dir", metavar="DIR", help="folder of the CA (from 'dfrl certs init')")
    n.add_argument(
        "--out",
        metavar="NODE_DIR",
        type=Path,
        default=None,
        help="where to write ca.crt, node.crt, node.key (default: DIR/NAME)",
    )
    n.add_argument(
        "--force",
        action="store_true",
        help="replace a certificate already in NODE_DIR (default: refuse)",
    )
    n.set_defaults(func=_node)
    c = sub.add_parser(
        "cluster",
        help="make a Dask cluster member's certificate (scheduler, worker host, "
        "driver), signed by the cluster CA kept in DIR/cluster-ca",
        description="A certificate for a member of the Dask cluster of 'dfrl run --cluster "
        "tls://...'. The cluster has a CA of its own, DIR/cluster-ca, made by the "
        "first call: node certificates open no cluster, cluster certificates no "
        "node. Any holder of a cluster certificate can run code on every worker: "
        "give them only to hosts trusted like robot hosts.",
    )
    c.add_argument(
        "name",
        metavar="NAME",
        help="the member's name: the certificate's CN and subjectAltName DNS entry",
    )
    c.add_argument("dir", metavar="DIR", help="folder of the project CA (from 'dfrl certs init')")
    c.add_argument(
        "--out",
        metavar="CLUSTER_DIR",
        type=Path,
        default=None,
        help="where to write ca.crt, cluster.crt, cluster.key (default: DIR/cluster-ca/NAME)",
    )
    c.add_argument(
        "--force",
        action="store_true",
        help="replace a certificate already in CLUSTER_DIR (default: refuse)",
    )
    c.set_defaults(func=_cluster)
