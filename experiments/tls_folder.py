"""A platform node's TLS folder: its file names, the names a certificate may carry, its check.

A node's TLS folder (the platform's ``tls(Dir)`` option, ``--tls DIR`` on the command line)::

    NODE_DIR/ca.crt     the project CA's certificate (what peers are checked against)
    NODE_DIR/node.crt   the node's certificate: CN and subjectAltName DNS = its name
    NODE_DIR/node.key   its private key (mode 0600)

``dfrl certs`` makes such folders (:mod:`dfrl.experiments.tools.certs`); the driver, the robot
host and ``dfrl node`` only check them here (:func:`check_node_dir`) before a node starts.

A cluster member's folder (the Dask scheduler's, a worker's or the driver's on a ``dfrl run
--cluster tls://...`` cluster; ``--cluster-tls DIR``, ``dask ... --tls-*``)::

    CLUSTER_DIR/ca.crt        the cluster CA's certificate (kept beside the project CA, in
                              CA_DIR/cluster-ca/; not the project CA: see tools/certs.py)
    CLUSTER_DIR/cluster.crt   the member's certificate: CN and subjectAltName DNS = its name
    CLUSTER_DIR/cluster.key   its private key (mode 0600)

The names differ from a node folder's so that one is never taken for the other.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from dfrl.experiments.errors import ExperimentError

CA_CERT = "ca.crt"
NODE_CERT = "node.crt"
NODE_KEY = "node.key"
NODE_FILES = (CA_CERT, NODE_CERT, NODE_KEY)
CLUSTER_CERT = "cluster.crt"
CLUSTER_KEY = "cluster.key"
CLUSTER_FILES = (CA_CERT, CLUSTER_CERT, CLUSTER_KEY)

#: A node name: what a DNS label sequence allows (letters, digits, ``-``, ``.``), at most 64
#: characters (the X.509 limit for a common name), starting and ending with a letter or digit.
NAME_RE = re.compile(r"^[A-Za-z0-9](?:[A-Za-z0-9.-]{0,62}[A-Za-z0-9])?$")


class CertError(ExperimentError):
    """A node's TLS folder or certificate is not usable: a bad name, files missing or in the
    way, or ``openssl`` failed."""


def is_node_name(name: object) -> bool:
    """True if ``name`` can name a node in a certificate (:data:`NAME_RE`, no ``..``)."""
    return isinstance(name, str) and bool(NAME_RE.match(name)) and ".." not in name


def check_node_dir(directory: str | os.PathLike[str]) -> Path:
    """Return ``directory`` as a path if it holds a node's TLS files.

    Raises
    ------
    CertError
        A file of :data:`NODE_FILES` is missing.
    """
    return _check_dir(directory, NODE_FILES, "node")


def check_cluster_dir(directory: str | os.PathLike[str]) -> Path:
    """Return ``directory`` as a path if it holds a cluster member's TLS files.

    Raises
    ------
    CertError
        A file of :data:`CLUSTER_FILES` is missing.
    """
    return _check_dir(directory, CLUSTER_FILES, "cluster")


def _check_dir(directory: str | os.PathLike[str], files: tuple[str, ...], kind: str) -> Path:
    """``directory`` as a path if it holds every one of ``files``, else the error naming the
    missing ones and the ``dfrl certs KIND`` command that makes such a folder."""
    d = Path(directory)
    missing = [f for f in files if not (d / f).is_file()]
    if missing:
        raise CertError(
            f"{d} is not a {kind} TLS directory: missing {', '.join(missing)} "
            f"(make one with 'dfrl certs {kind} NAME CA_DIR --out DIR')"
        )
    return d
