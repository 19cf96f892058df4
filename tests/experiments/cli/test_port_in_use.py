"""A port that another process holds is named, with what holds it probably and what to do
(issue 36: "Address already in use" named no port): ``dfrl node``, ``dfrl robot``,
``dfrl view`` and ``dfrl run --view --view-port``, each started for real against a socket
this test binds and listens on. The control: the same commands on a free port start."""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from tests.platform.conftest import SWIPL, Proc

pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")


@pytest.fixture
def held_port() -> Iterator[int]:
    """A port of 127.0.0.1 a listening socket of this test holds."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        yield int(s.getsockname()[1])


def _env() -> dict[str, str]:
    return {**{k: v for k, v in os.environ.items() if k != "DFRL_TOKEN"}, "DFRL_TOKEN": "t" * 40}


def _results(tmp_path: Path) -> Path:
    """A results folder as far as ``dfrl view`` asks (a config.json)."""
    out = tmp_path / "res"
    out.mkdir()
    (out / "config.json").write_text("{}")
    return out


def _commands(tmp_path: Path, port: int) -> dict[str, tuple[list[str], str]]:
    """What is started, and the option its message must name."""
    cfg = tmp_path / "cfg.json"
    cfg.write_text(
        json.dumps(
            {"name": "p", "iterations": 40, "respite": 20, "robots": [{"id": "r1", "arena": "r1"}]}
        )
    )
    return {
        "node": (["node", "--host", "127.0.0.1", "--port", str(port)], "--port"),
        "robot": (
            [
                "robot",
                "--host",
                "127.0.0.1",
                "--port",
                str(port),
                "--workdir",
                str(tmp_path / "work"),
            ],
            "--port",
        ),
        "view": (["view", str(_results(tmp_path)), "--port", str(port)], "--port"),
        "run --view": (
            ["run", str(cfg), "--out", str(tmp_path / "out"), "--view", "--view-port", str(port)],
            "--view-port",
        ),
    }


@pytest.mark.parametrize("command", ["node", "robot", "view", "run --view"])
def test_a_held_port_is_named_with_the_fix(command: str, held_port: int, tmp_path: Path) -> None:
    args, option = _commands(tmp_path, held_port)[command]
    run = subprocess.run(
        [sys.executable, "-m", "dfrl", *args],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
        env=_env(),
    )
    assert run.returncode in (1, 2), run.stderr
    assert f"port {held_port} on 127.0.0.1 is in use" in run.stderr, run.stderr
    assert f"pick another {option} (0: the OS chooses one) or stop what holds it" in run.stderr, (
        run.stderr
    )
    assert "Traceback" not in run.stderr, run.stderr


@pytest.mark.parametrize(
    "command, ready", [("node", "dfrl node listening on"), ("view", "dfrl view of")]
)
def test_the_control_a_free_port_serves(command: str, ready: str, tmp_path: Path) -> None:
    with socket.socket() as s:  # a port nobody holds any more
        s.bind(("127.0.0.1", 0))
        port = int(s.getsockname()[1])
    args, _ = _commands(tmp_path, port)[command]
    proc = Proc([sys.executable, "-m", "dfrl", *args], cwd=tmp_path, env=_env())
    try:
        assert f":{port}" in proc.wait_for(ready, timeout=120)
    finally:
        proc.stop()
