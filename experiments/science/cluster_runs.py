"""A study's federated runs spread over a Dask cluster: ``dfrl paper --cluster ADDRESS``.

Each federated run is one ``dfrl run CONFIG --cluster ADDRESS`` child process (its robots placed
on the cluster's workers, :mod:`dfrl.experiments.driver.launcher.cluster`), and as many run at
once as the cluster holds: its workers' ``CPU`` resource divided by what one run's robots ask
for (:func:`runs_at_once`). A run is a child process, not a thread, so that stopping the study
(SIGTERM, Ctrl-C) stops every run it started the way ``dfrl run`` is stopped: SIGTERM, the
robots save their tables, and the run's folder says it was interrupted.

Only the robots go to the cluster: the study's standalone trainings and evaluations stay in
its local pool (they write files the study reads, and a worker's disk is not the driver's).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

from dfrl.experiments.driver.config import ExperimentConfig
from dfrl.experiments.errors import ExperimentError

#: Seconds between two looks at the running children; seconds a stopped child gets to save.
POLL_S = 0.5
STOP_S = 60.0


@dataclass(frozen=True)
class ClusterOptions:
    """Where a study's federated runs go: the scheduler, each robot's ``CPU`` request, the
    token file the workers' services prove (``dfrl.token`` beside every worker), the driver's
    cluster folder for a ``tls://`` scheduler, and whether a plaintext one off loopback is
    accepted (``--insecure``)."""

    address: str
    token_file: Path
    cpus: float = 1.0
    tls: Path | None = None
    insecure: bool = False


@dataclass(frozen=True)
class Finished:
    """One federated run's end: its exit status and wall time (seconds)."""

    out: Path
    exit: int
    wall: float

    @property
    def ok(self) -> bool:
        return self.exit == 0


def runs_at_once(opts: ClusterOptions, robots: int) -> int:
    """How many runs of ``robots`` robots the cluster holds at once (at least 1).

    Raises
    ------
    ExperimentError
        The engine is missing or the scheduler does not answer; an unsafe access
        (:class:`~dfrl.experiments.driver.launcher.cluster.ClusterAccessError`).
    """
    from dfrl.experiments.driver.launcher.cluster import ClusterPlacement, cluster_access

    access = cluster_access(opts.address, opts.tls, opts.insecure)
    placement = ClusterPlacement(access, opts.cpus, lambda _line: None).open()
    try:
        fits = sum(int(a // opts.cpus) for a in placement.offered().values())
    finally:
        placement.release()
    return max(1, fits // max(1, robots))


def run_argv(config_file: Path, out: Path, opts: ClusterOptions) -> list[str]:
    """The ``dfrl run`` command of one federated run on the cluster."""
    return [
        sys.executable,
        "-m",
        "dfrl",
        "run",
        str(config_file),
        "--out",
        str(out),
        "--force",
        "--cluster",
        opts.address,
        "--cluster-cpus",
        f"{opts.cpus:g}",
        "--token-file",
        str(opts.token_file),
        *(["--cluster-tls", str(opts.tls)] if opts.tls is not None else []),
        *(["--insecure"] if opts.insecure else []),
    ]


def run_on_cluster(
    runs: Sequence[tuple[ExperimentConfig, Path]],
    opts: ClusterOptions,
    at_once: int,
    done: Callable[[Finished], None],
    progress: TextIO | None = None,
) -> list[Finished]:
    """Run every ``(config, out)`` on the cluster, at most ``at_once`` at a time, calling
    ``done`` as each one ends (in this thread); returns them in the order they ended.

    Each config is written beside its folder (``out`` + ``.config.json``) and its run's output
    goes to ``out`` + ``.log``. If this raises (a signal, or ``done`` raised), every child
    still running is sent SIGTERM, given :data:`STOP_S` to save, then killed.
    """
    waiting = list(runs)
    running: dict[subprocess.Popen, tuple[Path, float]] = {}
    ended: list[Finished] = []
    try:
        while waiting or running:
            while waiting and len(running) < max(1, at_once):
                cfg, out = waiting.pop(0)
                running[_start(cfg, out, opts, progress)] = (out, time.monotonic())
            for proc, (out, t0) in list(running.items()):
                if proc.poll() is None:
                    continue
                del running[proc]
                end = Finished(out, proc.returncode, time.monotonic() - t0)
                ended.append(end)
                if progress is not None:
                    state = "done" if end.ok else f"FAILED (exit {end.exit}, see {_log(out)})"
                    print(
                        f"== {out.parent.name}/{out.name} on the cluster: {state} in "
                        f"{end.wall:.0f} s",
                        file=progress,
                        flush=True,
                    )
                done(end)
            time.sleep(POLL_S)
    except BaseException:
        _stop_all(list(running))
        raise
    return ended


def _log(out: Path) -> Path:
    return out.with_name(out.name + ".log")


def _start(
    cfg: ExperimentConfig, out: Path, opts: ClusterOptions, progress: TextIO | None
) -> subprocess.Popen:
    out.parent.mkdir(parents=True, exist_ok=True)
    config_file = out.with_name(out.name + ".config.json")
    config_file.write_text(json.dumps(cfg.public_dict(), indent=2), encoding="utf-8")
    if progress is not None:
        print(
            f"== {out.parent.name}/{cfg.name}: {len(cfg.robots)} robots, {cfg.iterations} "
            f"iterations, on cluster {opts.address}",
            file=progress,
            flush=True,
        )
    with open(_log(out), "w", encoding="utf-8") as log:
        try:
            return subprocess.Popen(
                run_argv(config_file, out, opts),
                stdin=subprocess.DEVNULL,
                stdout=log,
                stderr=subprocess.STDOUT,
                start_new_session=True,
            )
        except OSError as exc:
            raise ExperimentError(f"cannot start the run of {cfg.name}: {exc}") from None


def _stop_all(procs: list[subprocess.Popen]) -> None:
    """SIGTERM every child still running (its robots save), then kill what is left after
    :data:`STOP_S`."""
    for proc in procs:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
    deadline = time.monotonic() + STOP_S
    for proc in procs:
        try:
            proc.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=10)
