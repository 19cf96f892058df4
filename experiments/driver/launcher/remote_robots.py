"""Robots on other hosts: an already running ``dfrl robot`` service per robot (contract K5).

The launcher reaches each service only through its console node
(:meth:`dfrl.experiments.driver.console.node.ConsoleNode.robot`). :class:`RemoteRobot` (a
:class:`~.robots.Robot`) configures the robot (the arena file, when the config names one,
travels inside the configuration: hosts need no shared disk), starts it, follows it by polling
``status`` (:class:`StatusPoller`, one thread for all of them), tells it to stop, and at the end
copies every result file it lists (``files``) into the results folder chunk by chunk
(``fetch``).

A robot whose status cannot be read for :data:`LOST_AFTER_S` is *lost* until it answers
again; a robot in state ``failed`` is lost for good (its ``error`` text is the reason). Both
end up in the summary and make the run incomplete.

Threading: the poller thread calls :meth:`RemoteRobot.poll` and
:meth:`RemoteRobot.poll_samples`; the launcher's thread calls the rest. Every field both touch
is guarded by the robot's lock, which is never held during a request to the service.
"""

from __future__ import annotations

import base64
import json
import threading
import time
from pathlib import Path
from typing import Any

from dfrl.experiments.driver.config import RobotSpec
from dfrl.experiments.robot_host.config import RobotConfig
from dfrl.experiments.driver.console.channel import ConsoleRequestError
from dfrl.experiments.driver.console.node import ConsoleNode
from dfrl.experiments.driver.launcher.remote_hosts import (
    arena_payload,
    safe_relative,
    short_of_clones,
)
from dfrl.experiments.driver.launcher.robots import Address, EventHandler, Progress, RobotStatus
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.robot_host.lines import (
    Evaluation,
    Sample,
    parse_eval,
    parse_event,
    parse_sample,
)

#: Seconds without a status answer after which a remote robot counts as lost.
LOST_AFTER_S = 10.0
#: Seconds between two status polls of one robot.
POLL_S = 0.5
#: Bytes asked for per ``fetch`` (base64 makes the text frame 4/3 of it).
FETCH_CHUNK = 256 * 1024
#: States in which the service runs (or may still run) our experiment.
ACTIVE = ("configured", "running")
#: Seconds the service has to answer ``stop`` when the launcher asks (:meth:`request_stop`),
#: and at least when it insists (:meth:`RemoteRobot.stop`).
ASK_STOP_S = 10.0
INSIST_STOP_S = 5.0


class RemoteRobot:
    """One robot on a ``dfrl robot`` service (see the module doc).

    Parameters
    ----------
    robot : RobotSpec
        With ``robot_host`` set.
    cfg : RobotConfig
        Sent as the configuration's ``node`` (its ``out_dir`` is ignored by the service).
    console : ConsoleNode
    experiment : str
        Experiment id: the service keeps the files under ``WORKDIR/<experiment>/``.
    poller : StatusPoller
        Polls it once it started.
    on_event : EventHandler, optional
        Called from the poller's thread for every ``DFRL_EVENT`` line its lines gained (an
        agent read or wrote its table), as for a robot process of this host.
    """

    def __init__(
        self,
        robot: RobotSpec,
        cfg: RobotConfig,
        console: ConsoleNode,
        experiment: str,
        poller: StatusPoller,
        on_event: EventHandler | None = None,
    ) -> None:
        if robot.robot_host_address is None:
            raise ExperimentError(f"robot {robot.id} names no robot host")
        self._spec = robot
        self._cfg = cfg
        self._service: Address = robot.robot_host_address
        self._console = console
        self._experiment = experiment
        self._poller = poller
        self._on_event = on_event
        self._lock = threading.Lock()
        self._address: Address | None = None  # guarded by _lock, and so on below
        self._state = "unknown"
        self._iteration = 0
        self._shares = 0
        self._error: str | None = None
        self._stopped = False
        self._last_answer = time.monotonic()
        self._unreachable: str | None = None  # why the last poll failed
        self._down_since = 0.0
        self._outages: list[tuple[float, float, str]] = []  # (from, to, why), monotonic
        self._sample: Sample | None = None  # the newest DFRL_SAMPLE, not taken yet
        self._sample_error: str | None = None  # why the last read of them failed
        self._evals: list[Evaluation] = []  # DFRL_EVAL lines not taken yet
        self._lines_at = 0  # bytes of its lines file read (poller only)
        self._lines_rest = b""
        self._err_path: Path | None = None
        self._resumed: list[int] = []  # checkpoint iterations it was resumed at

    @property
    def spec(self) -> RobotSpec:
        return self._spec

    @property
    def config(self) -> RobotConfig:
        return self._cfg

    # -- what it is doing --------------------------------------------------------------------
    def _lost(self) -> str | None:
        """Why it counts as lost now (caller holds the lock)."""
        if self._state == "failed":
            return f"failed on its host: {self._error or 'no reason given'}"
        silent = time.monotonic() - self._last_answer
        if self._unreachable is not None and silent > LOST_AFTER_S:
            return f"unreachable for {silent:.0f} s: {self._unreachable}"
        return None

    def status(self) -> RobotStatus:
        with self._lock:
            lost = self._lost()
            return RobotStatus(
                address=self._address,
                iteration=self._iteration,
                shares=self._shares,
                done=self._state == "finished" or self._iteration >= self._cfg.iterations,
                running=not self._stopped and self._state != "failed" and lost is None,
                lost=lost,
                resumed=tuple(self._resumed),
                silent_since=self._down_since if self._unreachable is not None else None,
                answered_at=self._last_answer,
            )

    def take_progress(self) -> Progress:
        with self._lock:
            progress = Progress(
                sample=self._sample,
                evals=self._evals,
                error=self._sample_error,
                outages=self._outages,
            )
            self._sample, self._evals, self._outages = None, [], []
        return progress

    def log_tail(self, lines: int = 8) -> str:
        """Its stderr's last lines once gathered, else why it failed or cannot be reached."""
        with self._lock:
            path, why = self._err_path, self._error or self._unreachable or ""
        if path is None or not path.is_file():
            return why
        text = path.read_text(encoding="utf-8", errors="replace").splitlines()
        return "\n".join(text[-lines:])

    # -- the service -------------------------------------------------------------------------
    def _ask(self, request: str | dict[str, Any], timeout_s: float = 20.0) -> Any:
        return self._console.robot(self._service, request, timeout_s=timeout_s)

    def start(self) -> None:
        """Check the service is free, send the configuration, remember the address the agent
        will use (the one the config names: the driver reached it there), and start it.

        Raises
        ------
        ExperimentError
            Unreachable, busy with another experiment, or the configuration was refused.
        """
        where = f"{self._service[0]}:{self._service[1]}"
        try:
            status = self._ask("status")
        except ConsoleRequestError as exc:
            if not exc.token_refused:
                raise ExperimentError(f"robot {self._spec.id} (robot host {where}): {exc}") from exc
            raise ExperimentError(
                f"robot {self._spec.id}: its robot host {where} accepts none of this run's "
                f"tokens; run with the token that dfrl robot was started with there "
                f"(--token-file FILE, DFRL_TOKEN or the config's token), or restart that "
                f"dfrl robot with this run's token (its --token-file or DFRL_TOKEN)"
            ) from exc
        if status.get("state") in ACTIVE:
            raise ExperimentError(
                f"robot host {where} is busy with experiment "
                f"{status.get('experiment')!r} (state {status.get('state')})"
            )
        short_of_clones(where, status.get("clone_limit"), self._cfg.clone_limit)
        self._configure(resume=False)
        with self._lock:
            self._address = self._service
        self._ask("start")
        with self._lock:
            self._state = "running"
        self._poller.watch(self)

    def _configure(self, resume: bool) -> None:
        """Send our experiment's configuration (``resume``: from the checkpoint the service's
        workdir holds) and read the status it leads to."""
        name, arena = arena_payload(self._spec.arena)
        robot = {**self._cfg.public_dict(), "arena": name}  # the robot has its own token
        self._ask(
            {
                "configure": json.dumps(
                    {
                        "experiment": self._experiment,
                        "robot": robot,
                        "arena": arena,
                        "resume": resume,
                    }
                )
            }
        )
        self._update(self._ask("status"))

    def _restarted(self, status: dict[str, Any]) -> bool:
        """The service answers, idle and holding no experiment, while ours ran there and had
        iterations left: its process was restarted (its workdir keeps our checkpoint)."""
        with self._lock:
            ours = (
                not self._stopped
                and self._state in ("running", "configured")
                and self._iteration < self._cfg.iterations
            )
        return ours and status.get("state") == "idle" and status.get("experiment") is None

    def _resume(self) -> None:
        """Configure the restarted service with our experiment again, from its checkpoint,
        and start it: the robot rejoins (the agent visits its stop every round). A failure
        leaves it failed, with the reason."""
        try:
            self._configure(resume=True)
            self._ask("start")
        except ExperimentError as exc:
            with self._lock:
                self._state, self._error = "failed", f"restarted, could not resume: {exc}"
            return
        with self._lock:
            self._state = "running"
            self._resumed.append(self._iteration)

    def _update(self, status: dict[str, Any]) -> None:
        with self._lock:
            self._state = str(status.get("state"))
            self._iteration = int(status.get("iteration") or 0)
            self._shares = int(status.get("shares") or 0)
            self._error = status.get("error")

    def _stop(self, timeout_s: float) -> bool:
        with self._lock:
            if self._stopped:
                return True
            ask = self._state in ACTIVE or self._state == "finished"
        try:
            if ask:
                self._ask("stop", timeout_s=max(1.0, timeout_s))
        except ExperimentError as exc:
            with self._lock:
                self._unreachable = str(exc)
            return False
        with self._lock:
            self._stopped = True
        return True

    def request_stop(self) -> None:
        """Tell the service to end our experiment (it answers once it did)."""
        self._stop(ASK_STOP_S)

    def stop(self, timeout_s: float) -> bool:
        """End the experiment on the service; True if it said so in time (at least
        :data:`INSIST_STOP_S` to answer)."""
        return self._stop(max(INSIST_STOP_S, timeout_s))

    @property
    def stopped(self) -> bool:
        """The launcher ended our experiment there (nothing more to poll)."""
        with self._lock:
            return self._stopped

    def poll(self) -> None:
        """Read the status once (a failure is remembered, never raised)."""
        try:
            status = self._ask("status", timeout_s=5.0)
        except ExperimentError as exc:
            with self._lock:
                if self._unreachable is None:
                    self._down_since = time.monotonic()
                self._unreachable = str(exc)
            return
        now = time.monotonic()
        with self._lock:
            if self._unreachable is not None:
                self._outages.append((self._down_since, now, self._unreachable))
            self._unreachable = None
            self._last_answer = now
        if isinstance(status, dict) and self._restarted(status):
            self._resume()
        elif isinstance(status, dict) and status.get("experiment") in (self._experiment, None):
            self._update(status)

    def answering(self) -> bool:
        """It runs or finished our experiment and its last poll was answered."""
        with self._lock:
            return self._state in ("running", "finished") and self._unreachable is None

    def poll_samples(self) -> None:
        """Read what the service's copy of our protocol lines (``logs/<robot>.out``, one of
        the result files) gained since the last read, and keep the newest ``DFRL_SAMPLE``
        (the live view's pose and curves) and every ``DFRL_EVAL``. A failure is remembered
        (the ``error`` of :meth:`take_progress`)."""
        try:
            chunk = self._ask(
                {
                    "fetch": {
                        "name": f"logs/{self._spec.id}.out",
                        "offset": self._lines_at,
                        "max": FETCH_CHUNK,
                    }
                },
                timeout_s=5.0,
            )
            data = base64.b64decode(chunk["data"])
        except (ExperimentError, KeyError, TypeError, ValueError) as exc:
            with self._lock:
                self._sample_error = f"{type(exc).__name__}: {exc}"
            return
        self._lines_at += len(data)
        data = self._lines_rest + data
        cut = data.rfind(b"\n") + 1
        self._lines_rest = data[cut:]
        lines = data[:cut].decode("utf-8", errors="replace").splitlines()
        sample = next((s for s in map(parse_sample, reversed(lines)) if s is not None), None)
        with self._lock:
            self._sample_error = None
            self._sample = sample or self._sample
            self._evals.extend(e for e in map(parse_eval, lines) if e is not None)
        if self._on_event is not None:
            for op, iteration in filter(None, map(parse_event, lines)):
                self._on_event(self._spec.id, op, iteration)

    def gather(self, out: Path) -> list[str]:
        """Read its last protocol lines (for the view's last events, unless it is lost), then
        copy every result file the service lists into ``out`` (same relative names); return
        the names copied.

        Raises
        ------
        ExperimentError
            The list or a chunk could not be read, or a file came back shorter than listed.
        """
        if self.status().lost is None:
            self.poll_samples()
        copied = fetch_files(self._console, self._service, self._spec.id, out)
        with self._lock:
            self._err_path = next(
                (out / c for c in copied if c.startswith("logs/") and c.endswith(".err")), None
            )
        return copied


def fetch_files(
    console: ConsoleNode, service: Address, robot: str, out: Path, timeout_s: float = 20.0
) -> list[str]:
    """Copy every result file the ``dfrl robot`` service at ``service`` lists (``files``: those
    of the experiment it holds) into ``out`` under the same relative names, chunk by chunk
    (``fetch``), each through a ``.part`` file; return the names copied. Used by
    :meth:`RemoteRobot.gather` at the end of a run and by ``dfrl collect`` after it.

    Raises
    ------
    ExperimentError
        The list or a chunk could not be read, or a file came back shorter than listed.
    """
    copied = []
    for entry in console.robot(service, "files", timeout_s=timeout_s):
        rel = safe_relative(str(entry["name"]))
        size = int(entry["size"])
        target = out / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        tmp = target.with_name(target.name + ".part")
        offset = 0
        with open(tmp, "wb") as fh:
            for _ in range(size // FETCH_CHUNK + 2):
                chunk = console.robot(
                    service,
                    {"fetch": {"name": str(rel), "offset": offset, "max": FETCH_CHUNK}},
                    timeout_s=timeout_s,
                )
                data = base64.b64decode(chunk["data"])
                fh.write(data)
                offset += len(data)
                if chunk["eof"] or not data:
                    break
        if offset < size:
            tmp.unlink()
            raise ExperimentError(f"robot {robot}: {rel} came back with {offset} of {size} bytes")
        tmp.replace(target)
        copied.append(str(rel))
    return copied


class StatusPoller:
    """One thread polling the status of every remote robot it watches (and its newest samples,
    see :meth:`RemoteRobot.poll_samples`) every :data:`POLL_S` until closed. The list it
    watches is guarded by its lock."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._robots: list[RemoteRobot] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="remote-status", daemon=True)

    def start(self) -> StatusPoller:
        self._thread.start()
        return self

    def watch(self, robot: RemoteRobot) -> None:
        """Poll ``robot`` from now on (until it is stopped)."""
        with self._lock:
            self._robots.append(robot)

    def _run(self) -> None:
        while not self._stop.wait(POLL_S):
            with self._lock:
                robots = list(self._robots)
            for robot in robots:
                if not robot.stopped and not self._stop.is_set():
                    robot.poll()
                    if robot.answering():
                        robot.poll_samples()

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=30.0)
