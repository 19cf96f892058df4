"""Helpers for tests that run real SWI-Prolog processes on loopback."""

from __future__ import annotations

import queue
import socket
import subprocess
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from dfrl.platform_pl import PLATFORM_DIR
from dfrl.experiments.processes import find_swipl

SWIPL = find_swipl()


def free_port() -> int:
    """A port the OS considers free right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Proc:
    """A subprocess whose output lines are collected by a reader thread."""

    def __init__(
        self, cmd: list[str], cwd: Path | None = None, env: dict[str, str] | None = None
    ) -> None:
        self.popen = subprocess.Popen(
            cmd,
            cwd=cwd,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            bufsize=1,
            env=env,
        )
        self.lines: list[str] = []
        self._q: queue.Queue[str] = queue.Queue()
        self._t = threading.Thread(target=self._read, daemon=True)
        self._t.start()

    def _read(self) -> None:
        assert self.popen.stdout is not None
        for line in self.popen.stdout:
            self.lines.append(line.rstrip("\n"))
            self._q.put(line)

    def wait_for(self, text: str, timeout: float = 20.0) -> str:
        """Wait for an output line containing ``text``; return it."""
        deadline = time.monotonic() + timeout
        for line in list(self.lines):
            if text in line:
                return line
        while time.monotonic() < deadline:
            try:
                line = self._q.get(timeout=max(0.01, deadline - time.monotonic()))
            except queue.Empty:
                break
            if text in line:
                return line.rstrip("\n")
        raise AssertionError(
            f"no line with {text!r} in time; output so far:\n" + "\n".join(self.lines)
        )

    def output(self) -> str:
        return "\n".join(self.lines)

    def stop(self) -> None:
        if self.popen.poll() is None:
            self.popen.kill()
        self.popen.wait(timeout=10)


@pytest.fixture
def procs() -> Iterator[list[Proc]]:
    """Processes started by a test; all killed at its end."""
    started: list[Proc] = []
    yield started
    for p in started:
        p.stop()
    for i, p in enumerate(started):  # shown by pytest only when the test failed
        print(f"--- process {i}: {' '.join(p.popen.args[:3])}\n{p.output()}")


def start_node(
    procs: list[Proc], *args: str, env: dict[str, str] | None = None
) -> tuple[Proc, int]:
    """Start ``node_main.pl`` with ``args`` (and environment ``env``, e.g. the node's tokens in
    ``DFRL_TOKEN``: ``dfrl.experiments.tokens.env_with_tokens``); return it and its port."""
    assert SWIPL, "swipl missing"
    p = Proc([SWIPL, "-q", str(PLATFORM_DIR / "node_main.pl"), *args], env=env)
    procs.append(p)
    line = p.wait_for("listening on")
    return p, int(line.rsplit(":", 1)[1])
