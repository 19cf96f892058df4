"""Where a run says what happens: progress lines on a text stream (stderr for ``dfrl run``) and
events of the live view in ``events.jsonl`` (:mod:`.events`). Safe from any thread."""

from __future__ import annotations

import threading
import time
from pathlib import Path
from typing import Any, TextIO

from dfrl.experiments.driver.launcher.events import append_event


class Reporter:
    """Progress lines and view events of one run, and the run's clock.

    Parameters
    ----------
    out : Path
        The results folder (``events.jsonl`` is written there).
    progress : TextIO or None
        Where progress lines go (None: quiet).
    """

    def __init__(self, out: Path, progress: TextIO | None) -> None:
        self._out = out
        self._progress = progress
        self._lock = threading.Lock()  # keeps lines whole; guards _t0
        self._t0 = time.monotonic()

    @property
    def quiet(self) -> bool:
        """No progress lines are written."""
        return self._progress is None

    def start_clock(self) -> float:
        """The run starts now (see :meth:`elapsed`); returns the start, a monotonic time."""
        with self._lock:
            self._t0 = time.monotonic()
            return self._t0

    def elapsed(self, at: float | None = None) -> float:
        """Seconds from the start of the run to ``at`` (a monotonic time; default now)."""
        with self._lock:
            return (time.monotonic() if at is None else at) - self._t0

    def say(self, text: str) -> None:
        """A progress line (nothing when quiet)."""
        if self._progress is None:
            return
        with self._lock:
            self._progress.write(text + "\n")
            self._progress.flush()

    def event(self, event: dict[str, Any]) -> None:
        """A line of ``events.jsonl`` for the live view; a failed write is said, never fatal
        to the run."""
        try:
            append_event(self._out, event)
        except (OSError, ValueError) as exc:
            self.say(f"could not write events.jsonl: {exc}")
