"""A project certificate authority and node certificates for mutual TLS, made with ``openssl``.

Layout (what ``dfrl certs`` writes and the platform's ``tls(Dir)`` option reads; the node
folder's names and its check are :mod:`dfrl.experiments.tls_folder`)::

    CA_DIR/ca.crt                      the project CA's certificate (self-signed)
    CA_DIR/ca.key                      its private key (mode 0600)
    NODE_DIR/ca.crt                    a copy of the CA certificate (what peers are checked against)
    NODE_DIR/node.crt                  the node's certificate: CN and subjectAltName DNS = its name
    NODE_DIR/node.key                  its private key (mode 0600)

Keys are ECDSA on P-256 (a short handshake); certificates are X.509 v3, the CA's with
``basicConstraints=critical,CA:TRUE``, a node's with ``CA:FALSE`` and both TLS usages
(``serverAuth``, ``clientAuth``), since every node is a server to some peers and a client of
others. Names are checked against an allow-list by the platform (``tls_peers(Names)``);
host names are not part of the check, so a node's name need not be its address.

The Dask cluster of ``dfrl run --cluster tls://...`` has a CA of its own, kept in the project
CA's folder and made by the first ``dfrl certs cluster`` (:func:`make_cluster_member`)::

    CA_DIR/cluster-ca/ca.crt           the cluster CA's certificate (self-signed)
    CA_DIR/cluster-ca/ca.key           its private key (mode 0600)
    CLUSTER_DIR/ca.crt                 a copy of the cluster CA certificate
    CLUSTER_DIR/cluster.crt            the member's certificate (scheduler, worker or driver)
    CLUSTER_DIR/cluster.key            its private key (mode 0600)

Why not the project CA itself: Dask checks only that a peer's certificate chains to its CA (no
name list), and any member of the cluster can run code on every worker, while the platform
accepts a node certificate and still sandboxes the agents of peers it does not trust
(``trusted_peers``). With one CA every node certificate would be a key to the workers; with
two, a node certificate opens no cluster and a cluster certificate no node.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

from dfrl.experiments.tls_folder import CA_CERT, CLUSTER_FILES, NODE_FILES, CertError, is_node_name

CA_KEY = "ca.key"
#: The cluster CA's folder inside the project CA's folder.
CLUSTER_CA = "cluster-ca"
CA_DAYS = 3650
NODE_DAYS = 825


@dataclass(frozen=True)
class NodeCert:
    """The files of one node certificate."""

    name: str
    directory: Path

    @property
    def files(self) -> tuple[Path, ...]:
        return tuple(self.directory / f for f in NODE_FILES)


def openssl() -> str:
    """The path of the ``openssl`` command.

    Raises
    ------
    CertError
        If it is not installed (Debian package ``openssl``).
    """
    path = shutil.which("openssl")
    if path is None:
        raise CertError("the openssl command is not installed (Debian package 'openssl')")
    return path


def check_name(name: str) -> str:
    """Return ``name`` if it can name a node in a certificate, else raise :class:`CertError`."""
    if not is_node_name(name):
        raise CertError(
            f"bad node name {name!r}: use 1-64 letters, digits, '-' or '.', "
            "starting and ending with a letter or digit"
        )
    return name


def _run(args: list[str], what: str) -> None:
    run = subprocess.run([openssl(), *args], capture_output=True, text=True, timeout=60)
    if run.returncode != 0:
        raise CertError(f"openssl failed to {what}: {run.stderr.strip() or run.stdout.strip()}")


def _refuse_existing(paths: list[Path], force: bool) -> None:
    present = [str(p) for p in paths if p.exists()]
    if present and not force:
        raise CertError(f"will not overwrite {', '.join(present)} (use --force)")


def _new_key(path: Path) -> None:
    """Write a new P-256 private key to ``path`` with mode 0600 from the start."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    os.close(fd)
    os.chmod(path, 0o600)
    _run(
        ["genpkey", "-algorithm", "EC", "-pkeyopt", "ec_paramgen_curve:P-256", "-out", str(path)],
        "make a private key",
    )
    os.chmod(path, 0o600)


def init_ca(
    directory: str | os.PathLike[str], force: bool = False, name: str = "dfrl project CA"
) -> Path:
    """Make a project CA in ``directory``: ``ca.crt`` and ``ca.key`` (mode 0600).

    Returns the CA certificate's path.

    Raises
    ------
    CertError
        If a CA is there already (and not ``force``), or openssl fails.
    """
    d = Path(directory)
    if d.exists() and not d.is_dir():
        raise CertError(f"{d} is not a directory")
    cert, key = d / CA_CERT, d / CA_KEY
    _refuse_existing([cert, key], force)
    d.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=d, prefix=".ca-") as tmp:
        tkey, tcert = Path(tmp) / CA_KEY, Path(tmp) / CA_CERT
        _new_key(tkey)
        _run(
            [
                "req",
                "-new",
                "-x509",
                "-key",
                str(tkey),
                "-out",
                str(tcert),
                "-days",
                str(CA_DAYS),
                "-sha256",
                "-subj",
                f"/CN={name}",
                "-addext",
                "basicConstraints=critical,CA:TRUE,pathlen:0",
                "-addext",
                "keyUsage=critical,keyCertSign,cRLSign",
                "-addext",
                "subjectKeyIdentifier=hash",
            ],
            "make the CA certificate",
        )
        os.replace(tkey, key)
        os.replace(tcert, cert)
    return cert


def make_node(
    name: str,
    ca_directory: str | os.PathLike[str],
    out: str | os.PathLike[str] | None = None,
    force: bool = False,
) -> NodeCert:
    """Make a certificate for node ``name`` signed by the CA in ``ca_directory``.

    Writes ``out/{ca.crt,node.crt,node.key}`` (default ``out``: ``ca_directory/name``); the
    certificate's CN and its subjectAltName DNS entry are ``name``.

    Raises
    ------
    CertError
        For a bad name, a missing CA, files in the way (and not ``force``), or openssl failing.
    """
    ca = Path(ca_directory)
    node_dir = Path(out) if out is not None else ca / name
    _sign(name, ca, node_dir, NODE_FILES, force)
    return NodeCert(name, node_dir)


def make_cluster_member(
    name: str,
    ca_directory: str | os.PathLike[str],
    out: str | os.PathLike[str] | None = None,
    force: bool = False,
) -> NodeCert:
    """Make a certificate for cluster member ``name`` (the scheduler, a worker's host, the
    driver) signed by the cluster CA of the project CA in ``ca_directory``.

    The cluster CA (``ca_directory/cluster-ca``) is made on the first call; the project CA
    must be there (``dfrl certs init``), so that both stay in one folder. Writes
    ``out/{ca.crt,cluster.crt,cluster.key}`` (default ``out``: ``ca_directory/cluster-ca/name``).

    Raises
    ------
    CertError
        For a bad name, a missing project CA, files in the way (and not ``force``), or openssl
        failing.
    """
    check_name(name)
    ca = Path(ca_directory)
    _require_ca(ca)
    cluster_ca = ca / CLUSTER_CA
    if not all((cluster_ca / f).is_file() for f in (CA_CERT, CA_KEY)):
        init_ca(cluster_ca, name="dfrl cluster CA")
    member_dir = Path(out) if out is not None else cluster_ca / name
    _sign(name, cluster_ca, member_dir, CLUSTER_FILES, force)
    return NodeCert(name, member_dir)


def _require_ca(ca: Path) -> None:
    for f in (ca / CA_CERT, ca / CA_KEY):
        if not f.is_file():
            raise CertError(f"no CA in {ca}: {f} is missing (make one with 'dfrl certs init {ca}')")


def _sign(name: str, ca: Path, out: Path, files: tuple[str, str, str], force: bool) -> None:
    """Write a new key and a certificate for ``name`` signed by the CA in ``ca`` to ``out``
    under ``files`` (the CA copy's, the certificate's and the key's names)."""
    check_name(name)
    _require_ca(ca)
    ca_cert, ca_key = ca / CA_CERT, ca / CA_KEY
    if out.exists() and not out.is_dir():
        raise CertError(f"{out} is not a directory")
    _refuse_existing([out / f for f in files], force)
    out.mkdir(parents=True, exist_ok=True)
    copy_name, cert_name, key_name = files
    with tempfile.TemporaryDirectory(dir=out, prefix=".node-") as tmp:
        t = Path(tmp)
        key, csr, cert, ext = t / key_name, t / "req.csr", t / cert_name, t / "ext.cnf"
        _new_key(key)
        _run(
            ["req", "-new", "-key", str(key), "-out", str(csr), "-subj", f"/CN={name}"],
            "make the certificate request",
        )
        ext.write_text(
            "basicConstraints=critical,CA:FALSE\n"
            "keyUsage=critical,digitalSignature,keyEncipherment\n"
            "extendedKeyUsage=serverAuth,clientAuth\n"
            f"subjectAltName=DNS:{name}\n"
            "subjectKeyIdentifier=hash\n"
            "authorityKeyIdentifier=keyid\n"
        )
        _run(
            [
                "x509",
                "-req",
                "-in",
                str(csr),
                "-CA",
                str(ca_cert),
                "-CAkey",
                str(ca_key),
                "-set_serial",
                _serial(),
                "-out",
                str(cert),
                "-days",
                str(NODE_DAYS),
                "-sha256",
                "-extfile",
                str(ext),
            ],
            "sign the certificate",
        )
        shutil.copyfile(ca_cert, t / copy_name)
        for f in files:
            os.replace(t / f, out / f)


def _serial() -> str:
    """A random serial number of 128 bits (RFC 5280: positive, at most 20 octets)."""
    return "0x" + os.urandom(16).hex()


def certificate_subject(path: str | os.PathLike[str]) -> str:
    """The subject line openssl prints for a certificate (for messages and tests)."""
    run = subprocess.run(
        [openssl(), "x509", "-in", str(path), "-noout", "-subject", "-nameopt", "RFC2253"],
        capture_output=True,
        text=True,
        timeout=30,
    )
    if run.returncode != 0:
        raise CertError(f"cannot read certificate {path}: {run.stderr.strip()}")
    return run.stdout.strip().removeprefix("subject=")
