"""The live view's page has no authentication, so ``dfrl view`` (and ``dfrl run --view``)
refuses an address other than loopback unless told ``--insecure`` (``--view-insecure``), and
then warns on stderr (issue 36: ``dfrl view --host 0.0.0.0`` served an unauthenticated page
without a word). Real processes; the control: loopback serves without a warning."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading
import urllib.request
from pathlib import Path

import pytest

from dfrl.experiments.cli.view import is_loopback


def _results(tmp_path: Path) -> Path:
    out = tmp_path / "res"
    out.mkdir()
    (out / "config.json").write_text(json.dumps({"name": "v"}))
    return out


def _serve(tmp_path: Path, *options: str) -> tuple[str, str]:
    """Start ``dfrl view`` with ``options``, read the page it says it serves, stop it with
    Ctrl-C; (its stdout line, its stderr)."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "dfrl", "view", str(_results(tmp_path)), *options],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=tmp_path,
    )
    guard = threading.Timer(120, proc.kill)  # a view that never says where: killed
    guard.start()
    try:
        assert proc.stdout is not None
        line = proc.stdout.readline()
        assert "dfrl view of" in line, (line, proc.poll())
        port = line.split("at http://")[1].split("/")[0].rsplit(":", 1)[1]
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=30) as page:
            assert page.status == 200
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    finally:
        guard.cancel()
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
    return line, err


def test_every_interface_is_refused_without_insecure(tmp_path: Path) -> None:
    run = subprocess.run(
        [sys.executable, "-m", "dfrl", "view", str(_results(tmp_path)), "--host", "0.0.0.0"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert run.returncode == 2, run.stderr
    assert "--host 0.0.0.0 would serve the run's page, which has no authentication" in run.stderr
    assert "give --insecure to serve it anyway" in run.stderr
    assert run.stdout == ""  # it never served


def test_insecure_serves_with_a_warning_on_stderr(tmp_path: Path) -> None:
    line, err = _serve(tmp_path, "--host", "0.0.0.0", "--insecure")
    assert "http://0.0.0.0:" in line
    assert "WARNING: the view on 0.0.0.0 has no authentication (--insecure)" in err, err


def test_the_control_loopback_serves_without_a_warning(tmp_path: Path) -> None:
    line, err = _serve(tmp_path)
    assert "http://127.0.0.1:" in line
    assert "WARNING" not in err, err


def test_dfrl_run_refuses_an_exposed_view_before_anything_starts(tmp_path: Path) -> None:
    cfg = tmp_path / "cfg.json"
    cfg.write_text(
        json.dumps(
            {"name": "v", "iterations": 40, "respite": 20, "robots": [{"id": "r1", "arena": "r1"}]}
        )
    )
    run = subprocess.run(
        [
            sys.executable,
            "-m",
            "dfrl",
            "run",
            str(cfg),
            "--out",
            str(tmp_path / "out"),
            "--view",
            "--view-host",
            "0.0.0.0",
        ],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert run.returncode == 2, run.stderr
    assert "give --view-insecure to serve it anyway; nothing was started" in run.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(
    "host, loopback",
    [
        ("127.0.0.1", True),
        ("127.8.0.1", True),
        ("::1", True),
        ("[::1]", True),
        ("localhost", True),
        ("0.0.0.0", False),
        ("::", False),
        ("10.0.0.7", False),
        ("viewhost.example", False),
    ],
)
def test_what_counts_as_loopback(host: str, loopback: bool) -> None:
    assert is_loopback(host) is loopback
