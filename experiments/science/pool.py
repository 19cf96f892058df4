"""The worker processes of a study: :func:`study_pool` and :func:`stop_pool`.

A study runs its federations on a :class:`~concurrent.futures.ProcessPoolExecutor`. Two things
the executor does not do by itself: a forked worker inherits the study's SIGTERM handler (and
would outlive a study stopped with SIGTERM), and ``shutdown`` waits for running jobs and then
forgets its workers, so they must be taken before it to be ended at once.
"""

from __future__ import annotations

import signal
from concurrent.futures import ProcessPoolExecutor


def _worker_signals() -> None:
    """A worker ends on SIGTERM and leaves Ctrl-C to the study."""
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def study_pool(jobs: int) -> ProcessPoolExecutor:
    """``jobs`` (at least 1) worker processes that end on SIGTERM and ignore Ctrl-C."""
    return ProcessPoolExecutor(max_workers=max(1, jobs), initializer=_worker_signals)


def stop_pool(pool: ProcessPoolExecutor) -> None:
    """Cancel the pending jobs and end the workers now (the executor has no public way to
    end its workers before Python 3.14: its worker table is read before ``shutdown``, which
    clears it)."""
    workers = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for w in workers:
        w.terminate()
