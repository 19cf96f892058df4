"""``dfrl certs``: a project CA and node certificates (made with openssl)."""

from __future__ import annotations

import shutil
import stat
import subprocess
from pathlib import Path

import pytest

from dfrl.experiments.tls_folder import CertError
from dfrl.experiments.tools.certs import certificate_subject, init_ca, make_node
from dfrl.experiments.cli import main

pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="openssl missing")


def test_ca_and_node_certificate(tmp_path: Path) -> None:
    ca = tmp_path / "ca"
    assert main(["certs", "init", str(ca)]) == 0
    assert stat.S_IMODE((ca / "ca.key").stat().st_mode) == 0o600
    assert main(["certs", "node", "robot-1.lab", str(ca)]) == 0
    node = ca / "robot-1.lab"
    assert {p.name for p in node.iterdir()} == {"ca.crt", "node.crt", "node.key"}
    assert stat.S_IMODE((node / "node.key").stat().st_mode) == 0o600
    assert certificate_subject(node / "node.crt") == "CN=robot-1.lab"
    text = subprocess.run(
        ["openssl", "x509", "-in", str(node / "node.crt"), "-noout", "-text"],
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert "DNS:robot-1.lab" in text and "TLS Web Client Authentication" in text
    verify = subprocess.run(
        ["openssl", "verify", "-CAfile", str(ca / "ca.crt"), str(node / "node.crt")],
        capture_output=True,
        text=True,
    )
    assert verify.returncode == 0, verify.stderr


def test_refuses_to_overwrite_without_force(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    ca = tmp_path / "ca"
    init_ca(ca)
    key = (ca / "ca.key").read_bytes()
    assert main(["certs", "init", str(ca)]) == 2
    assert "--force" in capsys.readouterr().err
    assert (ca / "ca.key").read_bytes() == key
    make_node("n1", ca, out=tmp_path / "n1")
    with pytest.raises(CertError, match="will not overwrite"):
        make_node("n1", ca, out=tmp_path / "n1")
    old = (tmp_path / "n1" / "node.crt").read_bytes()
    make_node("n1", ca, out=tmp_path / "n1", force=True)
    assert (tmp_path / "n1" / "node.crt").read_bytes() != old


@pytest.mark.parametrize("name", ["", "a b", "-x", "x-", "a..b", "x" * 65, "a/b", "é"])
def test_bad_names_exit_2(name: str, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    init_ca(tmp_path / "ca")
    # "--": names that look like options reach the name check
    assert main(["certs", "node", "--", name, str(tmp_path / "ca")]) == 2
    assert "bad node name" in capsys.readouterr().err


def test_node_without_a_ca_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert main(["certs", "node", "n1", str(tmp_path / "none")]) == 2
    assert "dfrl certs init" in capsys.readouterr().err
