"""The robot process's stdout protocol lines and its stdin watch (the launcher's two channels)."""

from __future__ import annotations

import math
import os
import select
from typing import NamedTuple, TextIO, TypeVar

__all__ = ["Evaluation", "ProtocolLines", "Sample", "StdinWatch", "parse_eval", "parse_sample"]


class Sample(NamedTuple):
    """A ``DFRL_SAMPLE`` line, parsed."""

    robot: str
    iteration: int
    x: float
    y: float
    yaw: float
    q_sum: float
    cumulative_reward: float


_Measures = TypeVar("_Measures", "Sample", "Evaluation")


def parse_sample(line: str) -> Sample | None:
    """The sample a ``DFRL_SAMPLE`` line carries (None: not such a line, or malformed)."""
    return _parse_measures(line, "DFRL_SAMPLE", Sample)


def parse_event(line: str) -> tuple[str, int] | None:
    """``(op, iteration)`` of a ``DFRL_EVENT <robot> get|set <iteration>`` line (None: not
    such a line, or malformed): an agent read (``get``) or wrote (``set``) the robot's table."""
    parts = line.split()
    if (
        len(parts) != 4
        or parts[0] != "DFRL_EVENT"
        or parts[2] not in ("get", "set")
        or not parts[3].isdigit()
    ):
        return None
    return parts[2], int(parts[3])


def _parse_measures(line: str, tag: str, kind: type[_Measures]) -> _Measures | None:
    """``<tag> <robot> <iteration> <float> ...`` as ``kind(robot, iteration, *floats)``, with
    as many floats as ``kind`` has fields after the first two; None if the line is another
    one, malformed, or carries a value that is not finite."""
    parts = line.split()
    if len(parts) != len(kind._fields) + 1 or parts[0] != tag:
        return None
    try:
        values = [float(v) for v in parts[3:]]
        parsed = kind(parts[1], int(parts[2]), *values)
    except ValueError:
        return None
    return parsed if all(math.isfinite(v) for v in values) else None


class Evaluation(NamedTuple):
    """A ``DFRL_EVAL`` line, parsed: a greedy evaluation's measures."""

    robot: str
    iteration: int
    collisions_per_1000: float
    progress: float
    coverage: float


def parse_eval(line: str) -> Evaluation | None:
    """The evaluation a ``DFRL_EVAL`` line carries (None: not such a line, or malformed)."""
    return _parse_measures(line, "DFRL_EVAL", Evaluation)


class ProtocolLines:
    """Writes the ``DFRL_*`` lines the launcher reads, one flushed line each.

    Parameters
    ----------
    out : TextIO
    robot : str
    events : bool
        Whether ``DFRL_EVENT`` lines are written.
    """

    def __init__(self, out: TextIO, robot: str, events: bool = True) -> None:
        self.out = out
        self.robot = robot
        self.events = events
        #: The reader went away (a broken pipe: the driver died); lines are dropped since.
        self.reader_gone = False

    def say(self, line: str) -> None:
        """Write one line and flush. When the reader is gone (the driver was killed), the
        line is dropped and so are all later ones: the robot goes on to its stop (its stdin
        is at end of file too) and saves its files instead of dying of a broken pipe."""
        if self.reader_gone:
            return
        try:
            self.out.write(line + "\n")
            self.out.flush()
        except BrokenPipeError:
            self.reader_gone = True
            self._drop_output()

    def _drop_output(self) -> None:
        """Point the stream's descriptor at /dev/null, so that nothing buffered in it (nor
        the interpreter's flush at exit) raises again."""
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            try:
                os.dup2(devnull, self.out.fileno())
            finally:
                os.close(devnull)
        except (OSError, ValueError):
            pass

    def node(self, host: str, port: int) -> None:
        """``DFRL_NODE <robot> <host> <port>``: the node listens."""
        self.say(f"DFRL_NODE {self.robot} {host} {port}")

    def progress(self, iteration: int) -> None:
        """``DFRL_PROGRESS <robot> <iteration>``."""
        self.say(f"DFRL_PROGRESS {self.robot} {iteration}")

    def event(self, what: str, iteration: int) -> None:
        """``DFRL_EVENT <robot> get|set <iteration>`` (if events are on)."""
        if self.events:
            self.say(f"DFRL_EVENT {self.robot} {what} {iteration}")

    def sample(
        self,
        iteration: int,
        pose: tuple[float, float, float],
        q_sum: float,
        cumulative_reward: float,
    ) -> None:
        """``DFRL_SAMPLE <robot> <iteration> <x> <y> <yaw> <q_sum> <cumulative_reward>``:
        where the robot is and how its curves stand, for the live view (if events are on;
        the run writes one now and then, see :data:`~.run.SAMPLE_S`)."""
        if self.events:
            x, y, yaw = (float(v) for v in pose)
            self.say(
                f"DFRL_SAMPLE {self.robot} {iteration} {x:.4f} {y:.4f} {yaw:.4f} "
                f"{float(q_sum)!r} {float(cumulative_reward)!r}"
            )

    def evaluation(
        self, iteration: int, collisions_per_1000: float, progress: float, coverage: float
    ) -> None:
        """``DFRL_EVAL <robot> <iteration> <collisions_per_1000> <progress> <coverage>``: a
        greedy evaluation of the table at this iteration (if events are on; see
        :mod:`.evaluate`)."""
        if self.events:
            self.say(
                f"DFRL_EVAL {self.robot} {iteration} {float(collisions_per_1000)!r} "
                f"{float(progress)!r} {float(coverage)!r}"
            )

    def done(self, iterations: int, shares: int) -> None:
        """``DFRL_DONE <robot> <iterations> <shares>``."""
        self.say(f"DFRL_DONE {self.robot} {iterations} {shares}")


class StdinWatch:
    """Non-blocking check whether the launcher closed our stdin (or asked us to stop).

    A stdin that is already at end of file when the watch starts (``< /dev/null``, a closed
    pipe, no stdin at all) is no channel: the watch is then *detached* and never says stop
    (the process runs its iterations; signals stop it).
    """

    def __init__(self, stream: TextIO | None) -> None:
        fd = None
        if stream is not None and not stream.closed:
            try:
                fd = stream.fileno()
            except (OSError, ValueError):
                fd = None
        self.fd = fd
        self.closed = False
        self.detached = fd is None
        self._buf = b""
        if fd is not None and self.poll() and not self._buf:
            self.closed, self.detached, self.fd = False, True, None

    def poll(self) -> bool:
        """True once stdin reached EOF or a ``stop`` line arrived (never when detached)."""
        if self.detached or self.fd is None:  # detached: no descriptor
            return False
        if self.closed:
            return True
        try:
            ready, _, _ = select.select([self.fd], [], [], 0)
        except (OSError, ValueError):
            self.closed = True
            return True
        if ready:
            data = os.read(self.fd, 4096)
            if not data:
                self.closed = True
            else:
                self._buf += data
                if b"stop" in self._buf:
                    self.closed = True
        return self.closed
