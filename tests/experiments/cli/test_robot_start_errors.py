"""``dfrl robot`` that cannot start says why in words (issue 20): the README's
``dfrl robot --port 7001 --token 4242`` (the default host 0.0.0.0 with a 13-bit token) exits 1
with the platform's own message (bits, what is needed, ``dfrl secret``, ``--host 127.0.0.1``),
never a ``Term(...)`` repr; the same token on loopback and the README's ``--token-file`` of a
``dfrl secret`` token listen. Real processes.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from tests.platform.conftest import SWIPL, Proc

pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _dfrl(*args: str) -> list[str]:
    return [sys.executable, "-m", "dfrl", *args]


def _env() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k != "DFRL_TOKEN"}


def test_weak_token_on_every_interface_is_explained(tmp_path: Path) -> None:
    port = _free_port()
    run = subprocess.run(
        _dfrl("robot", "--port", str(port), "--token", "4242", "--workdir", str(tmp_path / "work")),
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
        env=_env(),
    )
    err = run.stderr
    assert run.returncode == 1, err
    assert "Term(" not in err and "Atom(" not in err, err
    assert "EXCEPTION" not in err, err
    assert "13 bits" in err and "128" in err and "dfrl secret" in err, err
    assert "--host 127.0.0.1" in err, err


def test_weak_token_on_loopback_listens(tmp_path: Path) -> None:
    proc = Proc(
        _dfrl(
            "robot",
            "--host",
            "127.0.0.1",
            "--port",
            "0",
            "--token",
            "4242",
            "--workdir",
            str(tmp_path / "work"),
        ),
        env=_env(),
        cwd=tmp_path,
    )
    try:
        assert "dfrl robot listening on 127.0.0.1:" in proc.wait_for("listening", timeout=120)
    finally:
        proc.stop()


def test_readme_token_file_command_listens(tmp_path: Path) -> None:
    made = subprocess.run(
        _dfrl("secret", "--out", "dfrl.token"),
        capture_output=True,
        text=True,
        timeout=60,
        cwd=tmp_path,
        env=_env(),
    )
    assert made.returncode == 0, made.stderr
    port = _free_port()
    proc = Proc(
        _dfrl(
            "robot",
            "--port",
            str(port),
            "--token-file",
            "dfrl.token",
            "--workdir",
            str(tmp_path / "work"),
        ),
        env=_env(),
        cwd=tmp_path,
    )
    try:
        assert f":{port}" in proc.wait_for("dfrl robot listening on", timeout=120)
    finally:
        proc.stop()
