"""``run(config, out, tls=DIR)`` and ``dfrl run/demo --tls DIR`` (issue 9): the console node and
every robot node spawned on this host speak mutual TLS with DIR's certificate; a sync run gives
the same results as a plaintext run with the same seed; a missing or incomplete TLS folder is
refused with exit status 2 before anything starts.
"""

from __future__ import annotations

import json
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from dfrl.experiments.tls_folder import CertError
from dfrl.experiments.tools.certs import init_ca, make_node
from dfrl.experiments.driver.launcher import join_robot, run

from .helpers import diagnose, rounds_csv, run_in_thread, small_config, wait_rounds
from dfrl.experiments.processes import find_swipl

pytestmark = [
    pytest.mark.skipif(find_swipl() is None, reason="needs swipl"),
    pytest.mark.skipif(shutil.which("openssl") is None, reason="needs openssl"),
]


@pytest.fixture(scope="module")
def node_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One node certificate (``local``) of a fresh project CA."""
    root = tmp_path_factory.mktemp("pki")
    init_ca(root / "ca")
    return make_node("local", root / "ca", root / "tls-local").directory


def _first_bytes(out: Path, box: dict[str, Any], timeout_s: float = 60.0) -> dict[str, bytes]:
    """Once ``OUT/nodes.json`` lists the robots and the console: what a plaintext client that
    connects to each of them and says nothing has received 1.5 s later (a plaintext platform
    node greets with its hello frame at once; a TLS node waits for a ClientHello)."""
    deadline = time.monotonic() + timeout_s
    info: dict[str, Any] = {}
    while time.monotonic() < deadline and "res" not in box and "exc" not in box:
        try:
            info = json.loads((out / "nodes.json").read_text(encoding="utf-8"))
        except (OSError, ValueError):
            info = {}
        if info.get("nodes") and info.get("console"):
            break
        time.sleep(0.02)
    assert info.get("nodes"), f"no nodes.json with nodes within {timeout_s} s: {box}"
    ports = {n["robot"]: int(n["port"]) for n in info["nodes"]}
    ports["console"] = int(info["console"][1])
    socks = {
        name: socket.create_connection(("127.0.0.1", port), timeout=5)
        for name, port in ports.items()
    }  # all at once: the run is short
    seen = {}
    try:
        time.sleep(1.5)
        for name, s in socks.items():
            s.settimeout(0.05)
            try:
                seen[name] = s.recv(64)
            except (TimeoutError, socket.timeout):
                seen[name] = b""
            except ConnectionResetError:
                seen[name] = b"<reset>"
    finally:
        for s in socks.values():
            s.close()
    return seen


def _run_probed(cfg: Any, out: Path, tls: Path | None) -> tuple[Any, dict[str, bytes]]:
    """``run(cfg, out, tls=tls)`` in a thread, probed by :func:`_first_bytes` while it runs."""
    t, box = run_in_thread(cfg, out, tls=tls)
    try:
        seen = _first_bytes(out, box)
    finally:
        t.join(timeout=180)
    assert not t.is_alive(), "the run did not end within 180 s"
    assert "exc" not in box, box.get("exc")
    return box["res"], seen


def test_tls_run_equals_the_plaintext_run(tmp_path: Path, node_dir: Path) -> None:
    cfg = small_config(2)
    plain, seen_plain = _run_probed(cfg, tmp_path / "plain", None)
    tls, seen_tls = _run_probed(cfg, tmp_path / "tls", node_dir)
    detail = diagnose(tmp_path / "plain", tmp_path / "tls")
    assert plain.ok and tls.ok, detail
    # the probe means something: plaintext nodes greet a silent client with their hello ...
    assert all(b.startswith(b"DFRL") for b in seen_plain.values()), seen_plain
    # ... TLS nodes (both robots and the console) never send a platform frame in the clear
    assert set(seen_tls) == {"r1", "r2", "console"}, seen_tls
    assert not any(b"DFRL" in b for b in seen_tls.values()), seen_tls
    for rid in ("r1", "r2"):
        spawned = json.loads((tmp_path / "tls" / "nodes" / f"{rid}.json").read_text())
        assert spawned["tls"] == str(node_dir.resolve())
    assert json.loads((tmp_path / "tls" / "nodes.json").read_text())["tls"] == str(
        node_dir.resolve()
    )
    # same seed, sync mode: the same learning, share for share
    assert (tmp_path / "plain/metrics.csv").read_bytes() == (
        tmp_path / "tls/metrics.csv"
    ).read_bytes(), detail
    for rid in ("r1", "r2"):
        assert (tmp_path / "plain/tables" / f"{rid}.npy").read_bytes() == (
            tmp_path / "tls/tables" / f"{rid}.npy"
        ).read_bytes(), rid
    rows_plain, rows_tls = rounds_csv(tmp_path / "plain"), rounds_csv(tmp_path / "tls")
    assert len(rows_tls) == 4 and all(r["all_equal"] == "true" for r in rows_tls), detail
    for key in ("visited", "digest_r1", "digest_r2"):
        assert [r[key] for r in rows_plain] == [r[key] for r in rows_tls], key


def test_run_refuses_an_incomplete_tls_folder_before_starting(
    tmp_path: Path, node_dir: Path
) -> None:
    partial = tmp_path / "partial"
    partial.mkdir()
    shutil.copy(node_dir / "ca.crt", partial)
    shutil.copy(node_dir / "node.crt", partial)
    with pytest.raises(CertError, match="node.key"):
        run(small_config(2), tmp_path / "out", progress=None, tls=partial)
    assert not (tmp_path / "out").exists()


def _dfrl(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "dfrl", *args], cwd=cwd, capture_output=True, text=True, timeout=60
    )


@pytest.mark.parametrize("command", [["run", "demo"], ["demo"]], ids=["run", "demo"])
def test_cli_bad_tls_folder_exits_2_and_starts_nothing(
    tmp_path: Path, node_dir: Path, command: list[str]
) -> None:
    partial = tmp_path / "partial"
    partial.mkdir()
    shutil.copy(node_dir / "node.key", partial)
    for tls, missing in (
        (tmp_path / "absent", "ca.crt, node.crt, node.key"),
        (partial, "ca.crt, node.crt"),
    ):
        out = tmp_path / f"out-{tls.name}"
        done = _dfrl(*command, "--tls", str(tls), "--out", str(out), cwd=tmp_path)
        assert done.returncode == 2, done.stderr
        assert f"missing {missing}" in done.stderr and "nothing was started" in done.stderr, (
            done.stderr
        )
        assert "dfrl certs node" in done.stderr, done.stderr
        assert not out.exists()
    assert not (tmp_path / "results").exists()


def test_help_names_the_default(tmp_path: Path) -> None:
    for command in ("run", "demo"):
        done = _dfrl(command, "--help", cwd=tmp_path)
        text = " ".join(done.stdout.split())
        assert "--tls DIR" in text and "default: none, plaintext" in text, text
        assert "one credential for all local processes" in text, text


def test_join_reaches_a_tls_run_with_its_folder(tmp_path: Path, node_dir: Path) -> None:
    """``dfrl join`` (join_robot) opens its own console node with the run's TLS folder
    (``nodes.json``); the launcher spawns the new robot with it too."""
    cfg = small_config(iterations=2000, respite=100, rtf=20.0)
    t, box = run_in_thread(cfg, tmp_path, tls=node_dir)
    wait_rounds(tmp_path, "fed_qlearning", 2)
    entry = join_robot(tmp_path, "r3", "r5", iterations=600)
    t.join(timeout=120)
    assert not t.is_alive()
    res = box.get("res") or pytest.fail(f"run failed: {box.get('exc')!r}")
    assert res.ok, diagnose(tmp_path)
    assert entry["robot"] == "r3" and entry["joined"] is True
    assert json.loads((tmp_path / "nodes" / "r3.json").read_text())["tls"] == str(
        node_dir.resolve()
    )
    visited = [r["visited"] for r in rounds_csv(tmp_path)]
    assert "r1 r2 r3" in visited and visited[0] == "r1 r2"
