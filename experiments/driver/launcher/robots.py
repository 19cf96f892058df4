"""The one interface the launcher has to a robot: :class:`Robot`, wherever the robot runs.

Two classes implement it: :class:`~dfrl.experiments.driver.launcher.children.RobotChild` (a
robot process this host starts) and
:class:`~dfrl.experiments.driver.launcher.remote_robots.RemoteRobot` (a robot on a ``dfrl
robot`` service of another host). The launcher's steps use only the members below; what a
robot is made of (a process, a service reached over the platform) stays inside its class.

A robot's life: made (nothing runs yet), :meth:`Robot.start` (its platform node comes up;
:meth:`Robot.status` gives its address once it is up), followed through :meth:`Robot.status`
and :meth:`Robot.take_progress`, ended with :meth:`Robot.request_stop` (every robot at once)
then :meth:`Robot.stop` (each, waiting), and its result files brought into the results folder
with :meth:`Robot.gather`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Protocol, runtime_checkable

from dfrl.experiments.driver.config import RobotSpec
from dfrl.experiments.robot_host.config import RobotConfig
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.robot_host.lines import Evaluation, Sample

#: Called with (robot id, op ``get``/``set``, iteration) for every ``DFRL_EVENT`` line of a
#: robot: an agent read or wrote its table.
EventHandler = Callable[[str, str, int], None]

Address = tuple[str, int]
"""A platform node's (host, port)."""


@dataclass(frozen=True)
class RobotStatus:
    """What a robot is doing now (a snapshot: it changes under the launcher's feet).

    Attributes
    ----------
    address : (str, int) or None
        Where agents reach its platform node; None until it is up.
    iteration : int
        Iterations learnt so far.
    shares : int
        Tables shared into it so far (as far as the robot said).
    done : bool
        It said it ran all its iterations.
    running : bool
        Its process runs, or its service still runs (or serves) this experiment.
    lost : str or None
        Why it counts as lost now (a process that exited with an error, a service that failed
        or stopped answering); None while it is fine. A lost robot may come back (a service
        that answers again).
    exit_code : int or None
        The exit code of a process of this host that ended; None while it runs and for a
        robot on another host (it has no process here).
    pid : int or None
        Its process id on this host; None for a robot on another host.
    resumed : tuple of int
        The iterations its checkpoint held each time it was resumed after its robot host was
        restarted (empty: never).
    silent_since : float or None
        For a robot on another host whose last status poll failed: since when (``time.monotonic``)
        it has not answered; None while it answers, and for a robot of this host.
    answered_at : float or None
        For a robot on another host: when (``time.monotonic``) it last answered a poll.
    """

    address: Address | None
    iteration: int
    shares: int
    done: bool
    running: bool
    lost: str | None = None
    exit_code: int | None = None
    pid: int | None = None
    resumed: tuple[int, ...] = ()
    silent_since: float | None = None
    answered_at: float | None = None


@dataclass(frozen=True)
class Progress:
    """What a robot reported for the live view since the last :meth:`Robot.take_progress`.

    Attributes
    ----------
    sample : Sample or None
        Its newest ``DFRL_SAMPLE`` (pose, sum of Q-values, cumulative reward); None when it
        wrote none since the last call.
    evals : list of Evaluation
        Its ``DFRL_EVAL`` lines since the last call, in order.
    error : str or None
        Why its lines could not be read (None: they could, or it is a local process).
    outages : list of (float, float, str)
        Spells in which it did not answer that ended since the last call: (from, to, why) in
        :func:`time.monotonic` seconds.
    """

    sample: Sample | None = None
    evals: list[Evaluation] = field(default_factory=list)
    error: str | None = None
    outages: list[tuple[float, float, str]] = field(default_factory=list)


@runtime_checkable
class Robot(Protocol):
    """One robot of a run, as the launcher sees it (see the module doc)."""

    @property
    def spec(self) -> RobotSpec:
        """The robot in the config (id, arena, algorithm, where it runs)."""
        ...

    @property
    def config(self) -> RobotConfig:
        """The configuration it runs (its iterations, seed, respite ...)."""
        ...

    def start(self) -> None:
        """Start it: its platform node comes up (its address then comes in :meth:`status`).

        Raises
        ------
        ExperimentError
            It could not be started (a process that cannot run, a busy or unreachable
            service, a refused configuration).
        """
        ...

    def status(self) -> RobotStatus:
        """What it is doing now (no side effects)."""
        ...

    def take_progress(self) -> Progress:
        """What it reported for the live view since the last call (taken: the next call
        returns only what came after)."""
        ...

    def request_stop(self) -> None:
        """Ask it to end (it saves its table), without waiting for it."""
        ...

    def stop(self, timeout_s: float) -> bool:
        """End it: ask it (if not asked yet), wait at most ``timeout_s`` for it to end, and
        force it then. True if it ended by itself."""
        ...

    def gather(self, out: Path) -> list[str]:
        """Bring its result files into the results folder ``out``; return their names
        relative to ``out`` (none for a process that wrote them there itself).

        Raises
        ------
        ExperimentError
            A file could not be fetched whole.
        """
        ...

    def log_tail(self, lines: int = 8) -> str:
        """The last lines of its stderr (or of why it failed), for a crash report."""
        ...


def await_ready(robots: Sequence[Robot], timeout_s: float = 120.0) -> None:
    """Wait until every robot (started) reports its address.

    Raises
    ------
    ExperimentError
        A robot ended, or did not come up within ``timeout_s`` (its exit code and stderr
        tail given).
    """
    deadline = time.monotonic() + timeout_s
    for robot in robots:
        ended_at: float | None = None
        while True:
            status = robot.status()
            if status.address is not None:
                break
            now = time.monotonic()
            if not status.running:  # its last lines may still be on their way: 1 s more
                ended_at = ended_at or now
            if now > deadline or (ended_at is not None and now - ended_at > 1.0):
                raise ExperimentError(
                    f"robot {robot.spec.id} did not start (exit code "
                    f"{status.exit_code}): {robot.log_tail()}"
                )
            time.sleep(0.02)
