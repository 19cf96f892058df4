"""A robot process on this host (:mod:`dfrl.experiments.robot_host`) and what its stdout says.

Used by the launcher and by ``dfrl bench round``. The child runs ``python -m
dfrl.experiments.robot_host --config NODE.json`` in its own process group
(:func:`dfrl.experiments.processes.start`), with the results folder as its working directory
and the ``dfrl`` package that this process imported first on its ``PYTHONPATH`` (so it runs
the same code, installed or not). Its protocol: it prints ``DFRL_*`` lines on stdout and ends
when its stdin closes; one that does not end in time is stopped by
:func:`dfrl.experiments.processes.stop`.

Threading: one reader thread per child parses its stdout; what it learns (address,
iteration, samples ...) is guarded by the child's lock, and the event handler is called
outside it.
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import dfrl
from dfrl.experiments import processes
from dfrl.experiments.driver.config import RobotSpec
from dfrl.experiments.robot_host.config import RobotConfig
from dfrl.experiments.driver.launcher.robots import Address, EventHandler, Progress, RobotStatus
from dfrl.experiments.driver.results.files import write_json
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.robot_host.lines import (
    Evaluation,
    Sample,
    parse_eval,
    parse_event,
    parse_sample,
)
from dfrl.experiments.tokens import Token, env_with_tokens


def child_env(tokens: Sequence[Token] = ()) -> dict[str, str]:
    """Environment of a Python child: unbuffered, importing this process's ``dfrl``, with
    ``tokens`` in ``DFRL_TOKEN`` (none: no such variable, not even one this process got)."""
    root = str(Path(dfrl.__file__).resolve().parent.parent)
    path = os.environ.get("PYTHONPATH")
    return env_with_tokens(
        tokens,
        dict(
            os.environ,
            PYTHONUNBUFFERED="1",
            PYTHONPATH=root if not path else os.pathsep.join([root, path]),
        ),
    )


class RobotChild:
    """A robot process of this host (a :class:`~.robots.Robot`).

    Parameters
    ----------
    robot : RobotSpec
    cfg : RobotConfig
        Written to ``OUT/nodes/<robot>.json`` without its token, which the process gets in
        its environment (``DFRL_TOKEN``, :mod:`dfrl.experiments.tokens`), at :meth:`start`.
    out_dir : Path
        Results folder (absolute); stderr goes to ``OUT/logs/<robot>.err``.
    on_event : EventHandler, optional
        Called from the reader thread for every ``DFRL_EVENT`` line.
    module : str
        The module the child runs with ``python -m``: the robot process, or a tool's robot
        process with its probes installed (``dfrl bench round --trace``).
    """

    def __init__(
        self,
        robot: RobotSpec,
        cfg: RobotConfig,
        out_dir: Path,
        on_event: EventHandler | None = None,
        module: str = "dfrl.experiments.robot_host",
    ) -> None:
        self._spec = robot
        self._module = module
        self._cfg = cfg
        self._out = out_dir
        self._on_event = on_event
        self.err_path = out_dir / "logs" / f"{robot.id}.err"
        self._proc: subprocess.Popen[Any] | None = None
        self._reader: threading.Thread | None = None
        self._lock = threading.Lock()
        self._address: Address | None = None  # guarded by _lock, and so on below
        self._iteration = 0
        self._shares = 0
        self._done = False
        self._sample: Sample | None = None  # the newest, not taken yet
        self._evals: list[Evaluation] = []  # not taken yet

    @property
    def spec(self) -> RobotSpec:
        return self._spec

    @property
    def config(self) -> RobotConfig:
        return self._cfg

    def start(self) -> None:
        """Start the process (not waiting for it to come up).

        Raises
        ------
        ExperimentError
            Started already, or Python could not be started.
        """
        if self._proc is not None:
            raise ExperimentError(f"robot {self._spec.id} is started already")
        cfg_path = self._out / "nodes" / f"{self._spec.id}.json"
        write_json(cfg_path, self._cfg.public_dict())
        self.err_path.parent.mkdir(exist_ok=True)
        with open(self.err_path, "w", encoding="utf-8") as err:  # the child keeps its copy
            self._proc = processes.start(
                [sys.executable, "-m", self._module, "--config", str(cfg_path)],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=err,
                cwd=self._out,
                env=child_env(() if self._cfg.token is None else [self._cfg.token]),
                bufsize=1,
            )
        self._reader = threading.Thread(
            target=self._read, name=f"read-{self._spec.id}", daemon=True
        )
        self._reader.start()

    def _read(self) -> None:
        assert self._proc is not None and self._proc.stdout is not None
        for line in self._proc.stdout:
            parts = line.split()
            if not parts:
                continue
            tag = parts[0]
            if tag == "DFRL_EVENT":
                event = parse_event(line)
                if event is not None and self._on_event is not None:
                    self._on_event(self._spec.id, *event)
                continue
            with self._lock:
                if tag == "DFRL_NODE" and len(parts) == 4:
                    self._address = (parts[2], int(parts[3]))
                elif tag == "DFRL_PROGRESS" and len(parts) == 3:
                    self._iteration = int(parts[2])
                elif tag == "DFRL_SAMPLE":
                    self._sample = parse_sample(line) or self._sample
                elif tag == "DFRL_EVAL":
                    evaluation = parse_eval(line)
                    if evaluation is not None:
                        self._evals.append(evaluation)
                elif tag == "DFRL_DONE" and len(parts) == 4:
                    self._iteration = int(parts[2])
                    self._shares = int(parts[3])
                    self._done = True

    def status(self) -> RobotStatus:
        code = self._proc.poll() if self._proc is not None else None
        running = self._proc is not None and code is None
        with self._lock:
            return RobotStatus(
                address=self._address,
                iteration=self._iteration,
                shares=self._shares,
                done=self._done,
                running=running,
                lost=f"process exited with code {code}" if code else None,
                exit_code=code,
                pid=self._proc.pid if self._proc is not None else None,
            )

    def take_progress(self) -> Progress:
        with self._lock:
            progress = Progress(sample=self._sample, evals=self._evals)
            self._sample, self._evals = None, []
        return progress

    def close_stdin(self) -> None:
        """Tell the process to end (it ends when its stdin closes)."""
        stdin = self._proc.stdin if self._proc is not None else None
        try:
            if stdin is not None and not stdin.closed:
                stdin.close()
        except OSError:
            pass

    def request_stop(self) -> None:
        self.close_stdin()

    def stop(self, timeout_s: float) -> bool:
        """Close its stdin, wait up to ``timeout_s``, then
        :func:`~dfrl.experiments.processes.stop` it; True if it exited by itself."""
        if self._proc is None:
            return True
        self.close_stdin()
        by_itself = processes.wait_or_stop(self._proc, timeout_s)
        self._join_reader()
        return by_itself

    def _join_reader(self) -> None:
        """Wait (2 s at most) until its last stdout lines are read (once it ended)."""
        if self._reader is not None:
            self._reader.join(timeout=2)

    def gather(self, out: Path) -> list[str]:
        """Nothing to bring (the process wrote its files into the results folder): only read
        its last stdout lines (it ended)."""
        self._join_reader()
        return []

    def log_tail(self, lines: int = 8) -> str:
        """The last lines of its stderr (without pybullet's banner)."""
        try:
            text = self.err_path.read_text(encoding="utf-8", errors="replace").splitlines()
        except OSError:
            return ""
        text = [t for t in text if not t.startswith("pybullet build time")]
        return "\n".join(text[-lines:])
