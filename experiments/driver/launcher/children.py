"""A robot node process (:mod:`dfrl.experiments.robot_host`) and what its stdout says.

Used by the launcher and by ``dfrl bench round``. The child runs ``python -m
dfrl.experiments.robot_host --config NODE.json`` in its own process group, with the results
folder as its working directory and the ``dfrl`` package that this process imported first on
its ``PYTHONPATH`` (so it runs the same code, installed or not).
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Sequence
from pathlib import Path
from typing import Callable

import dfrl
from dfrl.experiments.driver.config import RobotSpec
from dfrl.experiments.robot_host.config import RobotConfig
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.driver.results.files import write_json
from dfrl.experiments.robot_host.lines import Evaluation, Sample, parse_eval, parse_sample
from dfrl.experiments.tokens import Token, env_with_tokens

#: Called with (robot id, op ``get``/``set``, iteration) for every ``DFRL_EVENT`` line.
EventHandler = Callable[[str, str, int], None]


def child_env(tokens: Sequence[Token] = ()) -> dict[str, str]:
    """Environment of a Python child: unbuffered, importing this process's ``dfrl``, with
    ``tokens`` in ``DFRL_TOKEN`` (none: no such variable, not even one this process got)."""
    root = str(Path(dfrl.__file__).resolve().parent.parent)
    path = os.environ.get("PYTHONPATH")
    return env_with_tokens(tokens, dict(
        os.environ, PYTHONUNBUFFERED="1",
        PYTHONPATH=root if not path else os.pathsep.join([root, path])))


class RobotChild:
    """A robot node process: its address once up, its progress, its stderr file.

    Parameters
    ----------
    robot : RobotSpec
    cfg : RobotConfig
        Written to ``OUT/nodes/<robot>.json`` without its token, which the process gets in
        its environment (``DFRL_TOKEN``, :mod:`dfrl.experiments.tokens`), and handed to it.
    out_dir : Path
        Results folder (absolute); stderr goes to ``OUT/logs/<robot>.err``.
    on_event : EventHandler, optional
    """

    def __init__(self, robot: RobotSpec, cfg: RobotConfig, out_dir: Path,
                 on_event: EventHandler | None = None) -> None:
        self.robot = robot
        self.cfg = cfg
        cfg_path = out_dir / "nodes" / f"{robot.id}.json"
        write_json(cfg_path, cfg.public_dict())
        logs = out_dir / "logs"
        logs.mkdir(exist_ok=True)
        self.err_path = logs / f"{robot.id}.err"
        self._err = open(self.err_path, "w", encoding="utf-8")
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "dfrl.experiments.robot_host", "--config", str(cfg_path)],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=self._err, cwd=out_dir,
            env=child_env(() if cfg.token is None else [cfg.token]), text=True, bufsize=1,
            start_new_session=True)
        self.address: tuple[str, int] | None = None
        self.iteration = 0
        self.done = False
        self.shares = 0
        self.sample: Sample | None = None
        self.evals: deque[Evaluation] = deque()      # DFRL_EVAL lines not in the view yet
        self.ready = threading.Event()
        self._on_event = on_event
        self._reader = threading.Thread(target=self._read, name=f"read-{robot.id}", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            parts = line.split()
            if not parts:
                continue
            tag = parts[0]
            if tag == "DFRL_NODE" and len(parts) == 4:
                self.address = (parts[2], int(parts[3]))
                self.ready.set()
            elif tag == "DFRL_PROGRESS" and len(parts) == 3:
                self.iteration = int(parts[2])
            elif tag == "DFRL_EVENT" and len(parts) == 4:
                if self._on_event is not None:
                    self._on_event(self.robot.id, parts[2], int(parts[3]))
            elif tag == "DFRL_SAMPLE":
                self.sample = parse_sample(line)       # for the live view (state.py)
            elif tag == "DFRL_EVAL":
                evaluation = parse_eval(line)
                if evaluation is not None:
                    self.evals.append(evaluation)
            elif tag == "DFRL_DONE" and len(parts) == 4:
                self.iteration = int(parts[2])
                self.shares = int(parts[3])
                self.done = True
        self.ready.set()

    @property
    def running(self) -> bool:
        return self.proc.poll() is None

    @property
    def pid(self) -> int | None:
        return self.proc.pid

    def exit_code(self) -> int | None:
        """The process's exit code, None while it runs."""
        return self.proc.poll()

    def close_stdin(self) -> None:
        """Tell the node to stop (it stops when its stdin closes)."""
        try:
            if self.proc.stdin is not None and not self.proc.stdin.closed:
                self.proc.stdin.close()
        except OSError:
            pass

    def kill(self) -> None:
        """SIGTERM the process group, SIGKILL after 3 s."""
        if self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, signal.SIGTERM)
            except (ProcessLookupError, PermissionError):
                pass
            try:
                self.proc.wait(timeout=3)
            except subprocess.TimeoutExpired:
                try:
                    os.killpg(self.proc.pid, signal.SIGKILL)
                except (ProcessLookupError, PermissionError):
                    pass
                self.proc.wait(timeout=3)

    def stop(self, timeout_s: float) -> bool:
        """Close stdin and wait; kill after ``timeout_s``. True if it exited by itself."""
        self.close_stdin()
        try:
            self.proc.wait(timeout=max(0.1, timeout_s))
            return True
        except subprocess.TimeoutExpired:
            self.kill()
            return False

    def finish(self) -> None:
        """Join the stdout reader and close the stderr file (after the process ended)."""
        self._reader.join(timeout=2)
        self._err.close()

    def err_tail(self, lines: int = 8) -> str:
        """The last lines of its stderr (without pybullet's banner)."""
        try:
            text = self.err_path.read_text(encoding="utf-8", errors="replace").splitlines()
        except OSError:
            return ""
        text = [t for t in text if not t.startswith("pybullet build time")]
        return "\n".join(text[-lines:])


def await_ready(children: list[RobotChild], timeout_s: float = 120.0) -> None:
    """Wait until every child printed its address.

    Raises
    ------
    ExperimentError
        A child did not start within ``timeout_s`` (its exit code and stderr tail given).
    """
    deadline = time.monotonic() + timeout_s
    for child in children:
        if not child.ready.wait(max(0.0, deadline - time.monotonic())) or child.address is None:
            raise ExperimentError(f"robot {child.robot.id} did not start (exit code "
                                  f"{child.proc.poll()}): {child.err_tail()}")
