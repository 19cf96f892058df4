"""The two ``hostile_node.pl`` processes of ``dfrl bench hostile``: the target and the peer.

Each prints ``PORT N`` once it listens, event lines of the peer's agent (``DEPART``, ``HOP``,
``FAIL``, ``DONE``: fields separated by spaces) and one JSON line in reply to each command read
from its standard input (the target: ``probe.``, ``purge.``; the peer: ``relaunch.``).
"""

from __future__ import annotations

import json
import os
import queue
import subprocess
import threading
from pathlib import Path
from typing import Any

from dfrl.experiments import processes

SCRIPT = Path(__file__).resolve().parent / "hostile_node.pl"


class HostileNode:
    """A ``hostile_node.pl`` process; a reader thread parses its lines.

    Event lines go to ``events`` (under ``lock``), as tuples of their fields.

    Raises
    ------
    ExperimentError
        ``swipl`` is missing.
    RuntimeError
        The node did not print its port within 20 s.
    """

    def __init__(
        self,
        args: list[str],
        events: list[tuple],
        lock: threading.Lock,
        env: dict[str, str] | None = None,
    ) -> None:
        self.proc = processes.start(
            [processes.swipl(), "-q", str(SCRIPT), *args],
            env={**os.environ, **(env or {})},
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        self.events, self.lock = events, lock
        self.replies: queue.Queue[dict[str, Any]] = queue.Queue()
        self.other_lines = 0
        self.port: int | None = None
        self.ready = threading.Event()
        self.stderr: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()
        threading.Thread(target=self._read_err, daemon=True).start()
        if not self.ready.wait(20) or self.port is None:
            self.close()
            raise RuntimeError(f"node {args[0]} did not start: {''.join(self.stderr)[-2000:]}")

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            f = line.split()
            if not f:
                continue
            if f[0] == "PORT":
                self.port = int(f[1])
                self.ready.set()
            elif f[0] in ("DEPART", "HOP", "FAIL", "DONE"):
                with self.lock:
                    self.events.append((f[0], *f[1:]))
            elif f[0].startswith("{"):
                try:
                    self.replies.put(json.loads(line))
                except json.JSONDecodeError:
                    self.other_lines += 1
            else:
                self.other_lines += 1  # e.g. a log flood's lines
        self.ready.set()

    def command(self, name: str, timeout_s: float = 20.0) -> dict[str, Any]:
        """Send the node a command (the target: ``probe``, ``purge``; the peer: ``relaunch``);
        its JSON reply."""
        while not self.replies.empty():
            self.replies.get_nowait()
        assert self.proc.stdin is not None
        self.proc.stdin.write(f"{name}.\n")
        self.proc.stdin.flush()
        try:
            return self.replies.get(timeout=timeout_s)
        except queue.Empty:
            raise RuntimeError(f"the target did not answer {name} in {timeout_s:g} s") from None

    def _read_err(self) -> None:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:
            if len(self.stderr) < 200:
                self.stderr.append(line)

    def close(self) -> None:
        """Close its standard input (the node then halts); stop it if it has not in 10 s."""
        if self.proc.stdin:
            try:
                self.proc.stdin.close()
            except OSError:
                pass
        processes.wait_or_stop(self.proc, 10.0)
