"""Who ``dfrl run --cluster`` talks to, without namespaces: a plaintext ``tcp://`` scheduler off
loopback is refused unless ``--insecure`` (exit 2, the reason said, nothing started: not even
the engine imported), as are ``tls://`` without a cluster folder and the other mismatches; a
TLS cluster on loopback (a real scheduler and worker in this process, certificates of
``dfrl certs cluster``) serves a client with a member's folder and refuses one of another CA;
the README's recipe asks for TLS everywhere.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from dfrl.experiments.driver.launcher.cluster import (
    ClusterAccess,
    ClusterAccessError,
    ClusterPlacement,
    cluster_access,
)
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.tools.certs import init_ca, make_cluster_member, make_node

from .readme_cluster import cluster_blocks, flag

needs_openssl = pytest.mark.skipif(shutil.which("openssl") is None, reason="needs openssl")


@pytest.mark.parametrize(
    "address, accepted",
    [
        ("tcp://127.0.0.1:8786", True),
        ("tcp://localhost:8786", True),
        ("127.0.0.1:8786", True),
        ("tcp://[::1]:8786", True),
        ("tcp://127.9.9.9:1", True),
        ("inproc://192.0.2.2/1/1", True),
        ("tcp://10.0.0.1:8786", False),
        ("10.0.0.1:8786", False),
        ("tcp://HEAD:8786", False),
        ("tcp://127.0.0.1.example.org:8786", False),
        ("tcp://[fe80::1]:8786", False),
        ("ucx://127.0.0.1:8786", False),
        ("ws://127.0.0.1:8786", False),
    ],
)
def test_plaintext_is_accepted_on_loopback_only(address: str, accepted: bool) -> None:
    if accepted:
        assert cluster_access(address) == ClusterAccess(address)
    else:
        with pytest.raises(ClusterAccessError):
            cluster_access(address)
    assert cluster_access("tcp://10.0.0.1:8786", insecure=True).tls is None


def _dfrl(cwd: Path, *args: str) -> tuple[int, str, bool]:
    """``dfrl ARGS`` in a fresh interpreter: exit status, stderr, whether the engine was
    imported."""
    code = (
        "import sys; from dfrl.experiments.cli import main; c = main(sys.argv[1:]); "
        "print('ENGINE', 'distributed' in sys.modules); sys.exit(c)"
    )
    env = {k: v for k, v in os.environ.items() if k != "DFRL_TOKEN"}
    done = subprocess.run(
        [sys.executable, "-c", code, *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=120,
        env=env,
    )
    return done.returncode, done.stderr, "ENGINE True" in done.stdout


@needs_openssl
def test_a_plaintext_cluster_off_loopback_is_refused_unless_insecure(tmp_path: Path) -> None:
    code, err, engine = _dfrl(
        tmp_path, "run", "smoke2", "--cluster", "tcp://10.1.2.3:8786", "--out", "o"
    )
    assert code == 2 and not engine, err
    assert "plaintext TCP off loopback" in err and "--insecure" in err, err
    assert "--cluster tls://10.1.2.3:8786 --cluster-tls DIR" in err, err
    assert "nothing was started" in err and "Traceback" not in err, err
    assert not (tmp_path / "o").exists()
    # control: with --insecure the same command passes this check and stops at the next one
    # (no token), still before it connects
    code, err, engine = _dfrl(
        tmp_path, "run", "smoke2", "--cluster", "tcp://10.1.2.3:8786", "--insecure", "--out", "o"
    )
    assert code == 1 and "--token-file dfrl.token" in err and "plaintext" not in err, err
    # the study too
    from dfrl.experiments.cli import main

    token = tmp_path / "dfrl.token"
    assert main(["secret", "--out", str(token)]) == 0
    code, err, engine = _dfrl(
        tmp_path,
        "paper",
        "--out",
        "p",
        "--cluster",
        "tcp://10.1.2.3:8786",
        "--token-file",
        str(token),
    )
    assert code == 2 and "plaintext TCP off loopback" in err and not engine, err
    assert not (tmp_path / "p").exists()


@needs_openssl
def test_tls_needs_a_cluster_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    from dfrl.experiments.cli import main

    monkeypatch.chdir(tmp_path)
    init_ca(tmp_path / "ca")
    node = make_node("driver", tmp_path / "ca", out=tmp_path / "node").directory
    member = make_cluster_member("driver", tmp_path / "ca", out=tmp_path / "member").directory
    cases = [
        (["--cluster", "tls://10.1.2.3:8786"], "needs --cluster-tls DIR"),
        (
            ["--cluster", "tls://10.1.2.3:8786", "--cluster-tls", str(node)],
            "not a cluster TLS directory: missing cluster.crt, cluster.key",
        ),
        (
            ["--cluster", "tcp://10.1.2.3:8786", "--cluster-tls", str(member)],
            "--cluster-tls is for a tls:// scheduler",
        ),
        (["--insecure"], "--insecure is for --cluster"),
        (["--cluster-tls", str(member)], "--cluster-tls is for --cluster"),
    ]
    for args, said in cases:
        code = main(["run", "smoke2", *args, "--out", "o"])
        err = capsys.readouterr().err
        assert code == 2 and said in err and "nothing was started" in err, (args, err)
    assert not (tmp_path / "o").exists()
    access = cluster_access("tls://10.1.2.3:8786", member)
    assert access.tls == member.resolve()


@needs_openssl
def test_a_tls_cluster_serves_members_only(tmp_path: Path) -> None:
    """A real TLS scheduler and worker on loopback (this process) with certificates of
    ``dfrl certs cluster``: the driver's placement with a member's folder sees the worker's
    CPUs; one with a folder of another CA cannot connect."""
    from distributed import LocalCluster, Security

    init_ca(tmp_path / "ca")
    init_ca(tmp_path / "other")
    made = {
        n: make_cluster_member(n, tmp_path / "ca", out=tmp_path / n).directory
        for n in ("scheduler", "driver")
    }
    stranger = make_cluster_member("driver", tmp_path / "other", out=tmp_path / "x").directory
    s = made["scheduler"]
    sec = Security(
        tls_ca_file=str(s / "ca.crt"),
        tls_scheduler_cert=str(s / "cluster.crt"),
        tls_scheduler_key=str(s / "cluster.key"),
        tls_worker_cert=str(s / "cluster.crt"),
        tls_worker_key=str(s / "cluster.key"),
        tls_client_cert=str(s / "cluster.crt"),
        tls_client_key=str(s / "cluster.key"),
        require_encryption=True,
    )
    with LocalCluster(
        n_workers=1,
        threads_per_worker=1,
        processes=False,
        protocol="tls",
        host="127.0.0.1",
        dashboard_address="127.0.0.1:0",
        security=sec,
        resources={"CPU": 2},
    ) as lc:
        address = lc.scheduler_address
        assert address.startswith("tls://127.0.0.1:")
        placement = ClusterPlacement(cluster_access(address, made["driver"])).open()
        try:
            assert list(placement.offered().values()) == [2.0]
        finally:
            placement.release()
        with pytest.raises(ExperimentError, match="cannot connect"):
            ClusterPlacement(cluster_access(address, stranger)).open()
        assert json.dumps(placement.record()["cluster_tls"]) == json.dumps(
            str(made["driver"].resolve())
        )


def test_the_recipe_asks_for_tls_everywhere() -> None:
    """The README's commands as written: TLS addresses and flags for every server, their
    HTTP servers on loopback, the driver with its folder."""
    blocks = cluster_blocks()
    for kind in ("scheduler", "worker"):
        line = blocks[kind][1].strip()
        for name in ("--tls-ca-file", "--tls-cert", "--tls-key"):
            assert flag(line, name), line
        assert flag(line, "--dashboard-address").startswith("127.0.0.1:"), line
        assert "tcp://" not in line, line
    assert flag(blocks["scheduler"][1], "--protocol") == "tls"
    assert blocks["worker"][1].split()[2].startswith("tls://")
    assert flag(blocks["driver"][1], "--cluster").startswith("tls://")
    assert flag(blocks["driver"][1], "--cluster-tls")
    assert "dfrl certs cluster" in blocks["certs"][1]
