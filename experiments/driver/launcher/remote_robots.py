"""Robots on other hosts: an already running ``dfrl robot`` service per robot (contract K5).

The launcher reaches each service only through its console node
(:meth:`dfrl.experiments.driver.console_node.ConsoleNode.robot`): :class:`RemoteRobot` configures the
robot (the arena file, when the config names one, travels inside the configuration: hosts
need no shared disk), starts it, follows it by polling ``status`` (:class:`StatusPoller`, one
thread for all of them), tells it to stop, and at the end copies every result file it lists
(``files``) into the results folder chunk by chunk (``fetch``). It offers the same few
members as a local :class:`~dfrl.experiments.driver.launcher.children.RobotChild` (``address``,
``iteration``, ``running``, ``exit_code()``, ``stop()`` ...), so the launcher's steps treat
both alike.

A robot whose status cannot be read for :data:`LOST_AFTER_S` is *lost* until it answers
again; a robot in state ``failed`` is lost for good (its ``error`` text is the reason). Both
end up in the summary and make the run incomplete.
"""
from __future__ import annotations

import base64
import json
import socket
import threading
import time
from collections import deque
from pathlib import Path, PurePosixPath
from typing import Any

from dfrl.experiments.driver.config import ExperimentConfig, RobotSpec
from dfrl.experiments.robot_host.config import RobotConfig
from dfrl.experiments.driver.console_node import ConsoleNode
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.robot_host.lines import Evaluation, Sample, parse_eval, parse_sample

#: Seconds without a status answer after which a remote robot counts as lost.
LOST_AFTER_S = 10.0
#: Seconds between two status polls of one robot.
POLL_S = 0.5
#: Bytes asked for per ``fetch`` (base64 makes the text frame 4/3 of it).
FETCH_CHUNK = 256 * 1024
#: States in which the service runs (or may still run) our experiment.
ACTIVE = ("configured", "running")


def route_source(host: str, port: int = 9) -> str:
    """The local address this host uses towards ``host`` (its route's source address): the
    address at which a node of ours is reachable from there. No packet is sent.

    Raises
    ------
    ExperimentError
        ``host`` cannot be resolved or there is no route to it.
    """
    try:
        family = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)[0]
        with socket.socket(family[0], socket.SOCK_DGRAM) as s:
            s.connect(family[4])
            return str(s.getsockname()[0])
    except OSError as exc:
        raise ExperimentError(f"no route to robot host {host}: {exc}") from None


def console_host(config: ExperimentConfig) -> str:
    """Where the launcher's console node (and every robot it spawns itself) binds: the
    config's ``console``; else the route's source address towards the first remote robot;
    else 127.0.0.1 (every robot on this host)."""
    if config.console:
        return config.console
    remote = config.remote_robots()
    if remote:
        host, port = remote[0].robot_host_address or ("127.0.0.1", 9)
        return route_source(host, port)
    return "127.0.0.1"


def arena_payload(arena: str) -> tuple[str, dict[str, Any] | None]:
    """The ``node.arena`` name and the ``arena`` object of a configuration: a built-in name
    goes as it is (object None), an arena file as its JSON object (named by its stem).

    Raises
    ------
    ExperimentError
        The file cannot be read or is not a JSON object.
    """
    path = Path(arena)
    if not path.is_file():
        return arena, None
    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ExperimentError(f"arena file {path}: {exc}") from None
    if not isinstance(obj, dict):
        raise ExperimentError(f"arena file {path}: not a JSON object")
    return path.stem, obj


def safe_relative(name: str) -> PurePosixPath:
    """A file name a robot listed, as a path inside the results folder.

    Raises
    ------
    ExperimentError
        An absolute name or one that climbs out (``..``).
    """
    p = PurePosixPath(name)
    if not name or p.is_absolute() or ".." in p.parts or "\\" in name:
        raise ExperimentError(f"robot listed a file outside its folder: {name!r}")
    return p


class RemoteRobot:
    """One robot on a ``dfrl robot`` service (see the module doc).

    Parameters
    ----------
    robot : RobotSpec
        With ``node`` set.
    cfg : RobotConfig
        Sent as the configuration's ``node`` (its ``out_dir`` is ignored by the service).
    console : ConsoleNode
    experiment : str
        Experiment id: the service keeps the files under ``WORKDIR/<experiment>/``.
    """

    def __init__(self, robot: RobotSpec, cfg: RobotConfig, console: ConsoleNode,
                 experiment: str) -> None:
        assert robot.robot_host_address is not None
        self.robot = robot
        self.cfg = cfg
        self.node = robot.robot_host_address
        self.console = console
        self.experiment = experiment
        self.address: tuple[str, int] | None = None
        self.iteration = 0
        self.shares = 0
        self.done = False
        self.ready = threading.Event()
        self.state = "unknown"
        self.error: str | None = None
        self.advertised: tuple[str, int] | None = None
        self.last_answer = time.monotonic()
        self.unreachable: str | None = None          # why the last poll failed
        self.outages: list[tuple[float, float, str]] = []   # (from, to, why), monotonic times
        self._lock = threading.Lock()
        self.stopped = False
        self._down_since = 0.0
        self.err_path: Path | None = None
        self.sample: Sample | None = None            # the newest DFRL_SAMPLE it wrote
        self.sample_error: str | None = None         # why the last read of them failed
        self.evals: deque[Evaluation] = deque()      # DFRL_EVAL lines not in the view yet
        self._lines_at = 0                           # bytes of its lines file read
        self._lines_rest = b""

    # -- the members a RobotChild has -------------------------------------------------------
    @property
    def pid(self) -> int | None:
        return None

    @property
    def lost(self) -> str | None:
        """Why the robot counts as lost now (None while it answers and has not failed)."""
        if self.state == "failed":
            return f"failed on its host: {self.error or 'no reason given'}"
        if self.unreachable is not None and time.monotonic() - self.last_answer > LOST_AFTER_S:
            return f"unreachable for {time.monotonic() - self.last_answer:.0f} s: " \
                   f"{self.unreachable}"
        return None

    @property
    def running(self) -> bool:
        """The service runs our experiment or still serves it (finished, not stopped by us)."""
        return not self.stopped and self.state != "failed" and self.lost is None

    def exit_code(self) -> int | None:
        """None while running; 0 once stopped or finished cleanly; 1 failed or lost."""
        if self.running:
            return None
        return 1 if self.lost is not None else 0

    def err_tail(self, lines: int = 8) -> str:
        if self.err_path is None or not self.err_path.is_file():
            return self.error or self.unreachable or ""
        text = self.err_path.read_text(encoding="utf-8", errors="replace").splitlines()
        return "\n".join(text[-lines:])

    def close_stdin(self) -> None:
        """Tell the service to end our experiment (the local child's "stdin closes")."""
        self._stop()

    def stop(self, timeout_s: float) -> bool:
        """End the experiment on the service; True if it said so in time."""
        return self._stop(timeout_s)

    def kill(self) -> None:
        self._stop(5.0)

    def finish(self) -> None:
        """Nothing to join: the service outlives the experiment."""

    # -- the service ------------------------------------------------------------------------
    def _ask(self, request: str | dict[str, Any], timeout_s: float = 20.0) -> Any:
        return self.console.robot(self.node, request, timeout_s=timeout_s)

    def configure(self) -> None:
        """Check the service is free, send the configuration and remember the address the
        agent will use (the one the config names: the driver reached it there).

        Raises
        ------
        ExperimentError
            Unreachable, busy with another experiment, or the configuration was refused.
        """
        where = f"{self.node[0]}:{self.node[1]}"
        status = self._ask("status")
        if status.get("state") in ACTIVE:
            raise ExperimentError(f"robot node {where} is busy with experiment "
                                  f"{status.get('experiment')!r} (state {status.get('state')})")
        name, arena = arena_payload(self.robot.arena)
        node = {**self.cfg.public_dict(), "arena": name}   # the robot has its own token
        self._ask({"configure": json.dumps({"experiment": self.experiment, "node": node,
                                            "arena": arena})})
        self._update(self._ask("status"))
        addr = status.get("address")
        if isinstance(addr, list) and len(addr) == 2:
            self.advertised = (str(addr[0]), int(addr[1]))
        self.address = self.node
        self.ready.set()

    def start(self) -> None:
        self._ask("start")
        self.state = "running"

    def _stop(self, timeout_s: float = 10.0) -> bool:
        if self.stopped:
            return True
        try:
            if self.state in ACTIVE or self.state == "finished":
                self._ask("stop", timeout_s=max(1.0, timeout_s))
            self.stopped = True
            return True
        except ExperimentError as exc:
            self.unreachable = str(exc)
            return False

    def _update(self, status: dict[str, Any]) -> None:
        self.state = str(status.get("state"))
        self.iteration = int(status.get("iteration") or 0)
        self.shares = int(status.get("shares") or 0)
        self.error = status.get("error")
        self.done = self.state == "finished" or self.iteration >= self.cfg.iterations

    def poll(self) -> None:
        """Read the status once (a failure is remembered, never raised)."""
        try:
            status = self._ask("status", timeout_s=5.0)
        except ExperimentError as exc:
            if self.unreachable is None:
                self._down_since = time.monotonic()
            self.unreachable = str(exc)
            return
        now = time.monotonic()
        if self.unreachable is not None:
            with self._lock:
                self.outages.append((self._down_since, now, self.unreachable))
            self.unreachable = None
        self.last_answer = now
        if isinstance(status, dict) and status.get("experiment") in (self.experiment, None):
            self._update(status)

    def poll_samples(self) -> None:
        """Read what the service's copy of our protocol lines (``logs/<robot>.out``, one of
        the result files) gained since the last read, and keep the newest ``DFRL_SAMPLE``
        (the live view's pose and curves) and every ``DFRL_EVAL`` (in ``evals``). A failure
        is remembered in ``sample_error``."""
        try:
            chunk = self._ask({"fetch": {"name": f"logs/{self.robot.id}.out",
                                         "offset": self._lines_at, "max": FETCH_CHUNK}},
                              timeout_s=5.0)
            data = base64.b64decode(chunk["data"])
        except (ExperimentError, KeyError, TypeError, ValueError) as exc:
            self.sample_error = f"{type(exc).__name__}: {exc}"
            return
        self.sample_error = None
        self._lines_at += len(data)
        data = self._lines_rest + data
        cut = data.rfind(b"\n") + 1
        self._lines_rest = data[cut:]
        lines = data[:cut].decode("utf-8", errors="replace").splitlines()
        for line in reversed(lines):
            sample = parse_sample(line)
            if sample is not None:
                self.sample = sample
                break
        self.evals.extend(e for e in map(parse_eval, lines) if e is not None)

    def take_outages(self) -> list[tuple[float, float, str]]:
        """The outages (from, to, why) that ended since the last call."""
        with self._lock:
            taken, self.outages = self.outages, []
        return taken

    def gather(self, out: Path) -> list[str]:
        """Copy every result file the service lists into ``out`` (same relative names);
        return the names copied.

        Raises
        ------
        ExperimentError
            The list or a chunk could not be read, or a file came back shorter or longer than
            listed.
        """
        copied = []
        for entry in self._ask("files"):
            rel = safe_relative(str(entry["name"]))
            size = int(entry["size"])
            target = out / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            tmp = target.with_name(target.name + ".part")
            offset = 0
            with open(tmp, "wb") as fh:
                for _ in range(size // FETCH_CHUNK + 2):
                    chunk = self._ask({"fetch": {"name": str(rel), "offset": offset,
                                                 "max": FETCH_CHUNK}})
                    data = base64.b64decode(chunk["data"])
                    fh.write(data)
                    offset += len(data)
                    if chunk["eof"] or not data:
                        break
            if offset < size:
                tmp.unlink()
                raise ExperimentError(f"robot {self.robot.id}: {rel} came back with {offset} of "
                                      f"{size} bytes")
            tmp.replace(target)
            copied.append(str(rel))
        self.err_path = next((out / c for c in copied if c.startswith("logs/") and
                              c.endswith(".err")), None)
        return copied


class StatusPoller:
    """One thread polling every remote robot's status (and its newest samples, see
    :meth:`RemoteRobot.poll_samples`) every :data:`POLL_S` until stopped."""

    def __init__(self, robots: list[RemoteRobot]) -> None:
        self._robots = robots
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="remote-status", daemon=True)

    def start(self) -> StatusPoller:
        self._thread.start()
        return self

    def _run(self) -> None:
        while not self._stop.wait(POLL_S):
            for robot in list(self._robots):
                if not robot.stopped and not self._stop.is_set():
                    robot.poll()
                    if robot.state in ("running", "finished") and robot.unreachable is None:
                        robot.poll_samples()

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=30.0)
