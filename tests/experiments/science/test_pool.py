"""A study's worker processes end when the study stops them (science/pool.py): real worker
processes running a real job, not a stand-in."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

from dfrl.experiments.science.pool import stop_pool, study_pool


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state not in ("Z", "X")


def _running_workers(pool, fut) -> list[int]:  # noqa: ANN001
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and not fut.running():
        time.sleep(0.02)
    assert fut.running()
    return [p.pid for p in pool._processes.values()]


def _gone_within(pids: list[int], seconds: float) -> bool:
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and any(map(_alive, pids)):
        time.sleep(0.05)
    return not any(map(_alive, pids))


def test_stop_pool_ends_a_worker_in_the_middle_of_a_job() -> None:
    pool = study_pool(1)
    pids = _running_workers(pool, pool.submit(time.sleep, 60))
    stop_pool(pool)
    assert _gone_within(pids, 10), pids


def test_shutdown_alone_forgets_its_workers_which_is_why_they_are_taken_first() -> None:
    # the control: the executor's own shutdown clears its worker table, so reading it
    # afterwards (as the paper's pool did) ends nothing
    pool = study_pool(1)
    pids = _running_workers(pool, pool.submit(time.sleep, 60))
    pool.shutdown(wait=False, cancel_futures=True)
    try:
        assert not (getattr(pool, "_processes", None) or {})
        assert all(map(_alive, pids))
    finally:
        for pid in pids:
            os.kill(pid, signal.SIGKILL)
    assert _gone_within(pids, 10)


def test_a_worker_ends_on_sigterm() -> None:
    pool = study_pool(1)
    pids = _running_workers(pool, pool.submit(time.sleep, 60))
    try:
        os.kill(pids[0], signal.SIGTERM)
        assert _gone_within(pids, 10)
    finally:
        stop_pool(pool)
