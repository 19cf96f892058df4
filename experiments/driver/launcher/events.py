"""The run's own event file, ``events.jsonl``: what no other results file says.

One JSON object per line, written by the launcher while the run goes on and read by the live
view (:mod:`dfrl.experiments.tools.view.source`)::

    {"t": 1796149725.77, "kind": "hop", "agent": "fed_qlearning", "robot": "r2",
     "phase": "forward" | "backward", "round": 3}
    {"t": ..., "kind": "robot_state", "robot": "r3", "state": "dead", "reason": "exit code -9"}
    {"t": ..., "kind": "pose", "robot": "r1", "iteration": 500, "x": 0.12, "y": -0.3,
     "yaw": 1.57}
    {"t": ..., "kind": "progress", "robot": "r4", "iteration": 500, "q_sum": 61.2,
     "cumulative_reward": 180.5, "shares": 1}
    {"t": ..., "kind": "eval", "robot": "r1", "iteration": 1000, "progress": 0.42,
     "collisions_per_1000": 3.0, "coverage": 0.31}

Poses come from the robots' ``DFRL_SAMPLE`` lines (at most one every
:data:`~dfrl.experiments.robot_host.training.SAMPLE_S`, with a progress line); a robot on a
``dfrl robot`` service sends the same lines into its ``logs/<robot>.out``, which the launcher
fetches as it grows, and its samples also become ``progress`` events (its metrics file comes
only at the end). Greedy evaluations (``eval_every``) come from ``DFRL_EVAL`` lines, the
same way.

``t`` is the writer's wall clock (:func:`time.time`), filled in when the event has none. Any
other ``kind`` is shown in the view's event list as it is.
"""

from __future__ import annotations

import json
import threading
import time
from pathlib import Path
from typing import Any

#: Name of the event file in a results folder.
EVENTS_FILE = "events.jsonl"

#: States a ``robot_state`` event may carry.
ROBOT_STATES = ("learning", "waiting", "stalled", "dead", "skipped", "done")

_lock = threading.Lock()


def append_event(out_dir: str | Path, event: dict[str, Any]) -> dict[str, Any]:
    """Append one event to ``OUT_DIR/events.jsonl`` (created if missing).

    The line is written with a single ``write`` on a file opened for appending, under a
    process-wide lock, so concurrent writers in this process never interleave and a reader
    sees whole lines (or a torn last line, which it reads again later).

    Parameters
    ----------
    out_dir : str or Path
        The results folder.
    event : dict
        Must have a string ``kind``; ``t`` is added (wall clock) when missing.

    Returns
    -------
    dict
        The event as written.

    Raises
    ------
    ValueError
        ``kind`` is missing, or the event is not JSON-serialisable.
    """
    if not isinstance(event.get("kind"), str) or not event["kind"]:
        raise ValueError(f"an event needs a string 'kind': {event!r}")
    ev = dict(event)
    ev.setdefault("t", time.time())
    try:
        line = json.dumps(ev, separators=(",", ":"), allow_nan=False) + "\n"
    except (TypeError, ValueError) as exc:
        raise ValueError(f"event is not JSON: {exc}") from exc
    path = Path(out_dir) / EVENTS_FILE
    with _lock, open(path, "a", encoding="utf-8") as fh:
        fh.write(line)
    return ev
