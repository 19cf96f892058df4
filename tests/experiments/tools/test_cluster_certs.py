"""``dfrl certs cluster``: a cluster member's folder, signed by the cluster CA that the first
call makes beside the project CA (not by the project CA: a node certificate must open no
cluster, a cluster certificate no node)."""

from __future__ import annotations

import shutil
import stat
import subprocess
from pathlib import Path

import pytest

from dfrl.experiments.cli import main
from dfrl.experiments.tls_folder import CertError, check_cluster_dir, check_node_dir
from dfrl.experiments.tools.certs import certificate_subject, init_ca, make_cluster_member

pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="openssl missing")


def _verifies(ca_cert: Path, cert: Path) -> bool:
    return (
        subprocess.run(
            ["openssl", "verify", "-CAfile", str(ca_cert), str(cert)],
            capture_output=True,
            text=True,
            timeout=30,
        ).returncode
        == 0
    )


def test_a_member_is_signed_by_the_cluster_ca_not_the_project_ca(tmp_path: Path) -> None:
    ca = tmp_path / "ca"
    assert main(["certs", "init", str(ca)]) == 0
    assert main(["certs", "cluster", "worker-1", str(ca), "--out", str(tmp_path / "w1")]) == 0
    assert main(["certs", "node", "robot-1", str(ca), "--out", str(tmp_path / "n1")]) == 0
    w1, n1 = tmp_path / "w1", tmp_path / "n1"
    assert {p.name for p in w1.iterdir()} == {"ca.crt", "cluster.crt", "cluster.key"}
    assert stat.S_IMODE((w1 / "cluster.key").stat().st_mode) == 0o600
    assert stat.S_IMODE((ca / "cluster-ca" / "ca.key").stat().st_mode) == 0o600
    assert certificate_subject(w1 / "cluster.crt") == "CN=worker-1"
    assert (w1 / "ca.crt").read_bytes() == (ca / "cluster-ca" / "ca.crt").read_bytes()
    assert _verifies(w1 / "ca.crt", w1 / "cluster.crt")
    # the two CAs do not vouch for each other's certificates (control: each its own)
    assert not _verifies(w1 / "ca.crt", n1 / "node.crt")
    assert not _verifies(ca / "ca.crt", w1 / "cluster.crt")
    assert _verifies(ca / "ca.crt", n1 / "node.crt")
    # a second member reuses the cluster CA the first one made
    make_cluster_member("driver", ca, out=tmp_path / "d")
    assert _verifies(w1 / "ca.crt", tmp_path / "d" / "cluster.crt")
    # a cluster folder is no node folder and the reverse
    assert check_cluster_dir(w1) == w1
    with pytest.raises(CertError, match="missing node.crt, node.key"):
        check_node_dir(w1)
    with pytest.raises(CertError, match="missing cluster.crt, cluster.key"):
        check_cluster_dir(n1)


def test_without_a_project_ca_or_over_a_member_it_refuses(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    assert main(["certs", "cluster", "w1", str(tmp_path / "none")]) == 2
    assert "dfrl certs init" in capsys.readouterr().err
    assert not (tmp_path / "none").exists()
    init_ca(tmp_path / "ca")
    make_cluster_member("w1", tmp_path / "ca")
    assert main(["certs", "cluster", "w1", str(tmp_path / "ca")]) == 2
    assert "--force" in capsys.readouterr().err
    assert main(["certs", "cluster", "bad name", str(tmp_path / "ca")]) == 2
