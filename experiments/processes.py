"""Child processes of every room: where ``swipl`` is, how a child starts, how it is stopped.

One place finds the SWI-Prolog executable (:func:`swipl`, one error when it is missing) and
one policy stops a child (:func:`stop`): SIGTERM to its process group, SIGKILL to the group
after a grace period, then reap. Children start in a session of their own
(:func:`start`), so the group holds the child and whatever it started, and a Ctrl-C at the
terminal reaches the parent only (which then stops its children in order).
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
from collections.abc import Mapping, Sequence
from typing import IO, Any

from dfrl.experiments.errors import ExperimentError

#: Seconds a child has between SIGTERM and SIGKILL.
GRACE_S = 3.0

_MISSING = "swipl is not installed (run scripts/setup.sh)"


def find_swipl() -> str | None:
    """The ``swipl`` executable on ``PATH``, None if there is none (for callers that skip)."""
    return shutil.which("swipl")


def swipl() -> str:
    """The ``swipl`` executable on ``PATH``.

    Raises
    ------
    ExperimentError
        SWI-Prolog is not installed.
    """
    path = find_swipl()
    if path is None:
        raise ExperimentError(_MISSING)
    return path


def start(
    argv: Sequence[str],
    *,
    stdin: int | IO[Any] | None = subprocess.DEVNULL,
    stdout: int | IO[Any] | None = None,
    stderr: int | IO[Any] | None = None,
    env: Mapping[str, str] | None = None,
    cwd: str | os.PathLike[str] | None = None,
    text: bool = True,
    bufsize: int = -1,
) -> subprocess.Popen[Any]:
    """Start ``argv`` in a session (and so a process group) of its own.

    ``stdin`` defaults to ``/dev/null``: a child never reads the terminal. With ``text`` the
    pipes are UTF-8 text (``bufsize=1`` makes them line buffered).

    Raises
    ------
    ExperimentError
        The executable could not be started (missing, not executable).
    """
    try:
        return subprocess.Popen(
            list(argv),
            stdin=stdin,
            stdout=stdout,
            stderr=stderr,
            env=None if env is None else dict(env),
            cwd=cwd,
            text=text,
            encoding="utf-8" if text else None,
            bufsize=bufsize,
            start_new_session=True,
        )
    except OSError as exc:
        raise ExperimentError(f"could not start {argv[0]}: {exc.strerror or exc}") from exc


def _signal_group(proc: subprocess.Popen[Any], sig: int) -> None:
    try:
        os.killpg(proc.pid, sig)
    except (ProcessLookupError, PermissionError):
        pass


def stop(proc: subprocess.Popen[Any], grace_s: float = GRACE_S) -> int | None:
    """Stop ``proc`` and its process group: SIGTERM, SIGKILL after ``grace_s``, then reap.

    A child that already exited is only reaped. Returns its exit code (None if even SIGKILL
    left it running, e.g. stopped in uninterruptible sleep, after another ``grace_s``).
    """
    if proc.poll() is None:
        _signal_group(proc, signal.SIGTERM)
        try:
            proc.wait(timeout=grace_s)
        except subprocess.TimeoutExpired:
            _signal_group(proc, signal.SIGKILL)
            try:
                proc.wait(timeout=grace_s)
            except subprocess.TimeoutExpired:
                return None
    elif proc.pid:
        _signal_group(proc, signal.SIGKILL)  # what it left behind in its group
    return proc.returncode


def wait_or_stop(proc: subprocess.Popen[Any], timeout_s: float, grace_s: float = GRACE_S) -> bool:
    """Wait up to ``timeout_s`` for ``proc`` to exit by itself; :func:`stop` it otherwise.
    True if it exited by itself."""
    try:
        proc.wait(timeout=max(0.0, timeout_s))
        return True
    except subprocess.TimeoutExpired:
        stop(proc, grace_s)
        return False
