"""The federated runs of ``dfrl paper``: run (or reuse) each one, here one after the other or
on a Dask cluster several at once (:mod:`.cluster_runs`), and queue the greedy evaluations of
each run's table snapshots as soon as it ends (:class:`FederatedRuns`).
"""

from __future__ import annotations

import re
import signal
import time
from collections.abc import Sequence
from concurrent.futures import Executor, Future, as_completed
from pathlib import Path
from typing import TextIO

import numpy as np

from dfrl.experiments.driver.config import ExperimentConfig
from dfrl.experiments.driver.launcher import run
from dfrl.experiments.science.fed_replicas import replica_job
from dfrl.experiments.science.cluster_runs import (
    ClusterOptions,
    Finished,
    run_on_cluster,
    runs_at_once,
)
from dfrl.experiments.science.studies.history import Evaluator, PendingRows, history_tables, pick

#: One seed's runs: (key, config) in order.
SeedConfigs = dict[int, list[tuple[str, ExperimentConfig]]]
#: ``dfrl run``'s exit status when interrupted, and the signals that end a run from outside.
INTERRUPTED = (130, -signal.SIGTERM, -signal.SIGKILL)


class StudyInterrupted(KeyboardInterrupt):
    """SIGTERM or Ctrl-C stopped the study (a :class:`KeyboardInterrupt`, so that callers that
    only know Ctrl-C stop too)."""


def recorded_wall(d: Path) -> float:
    """The wall time a finished run's ``summary.md`` recorded (nan if none)."""
    try:
        m = re.search(
            r"^- wall time: ([0-9.]+) s$", (d / "summary.md").read_text(encoding="utf-8"), re.M
        )
    except OSError:
        return float("nan")
    return float(m.group(1)) if m else float("nan")


class FederatedRuns:
    """Every seed's federated runs under ``out/seed<S>/<name>``, and what came of them.

    Parameters
    ----------
    out : Path
        The study's folder.
    evaluators : dict
        Seed -> the :class:`Evaluator` its runs' snapshots are queued on.
    points, held_out
        Snapshots evaluated per robot; the arenas evaluated beside the robot's own.
    skip_existing : bool
        Reuse a run whose ``summary.md`` exists.
    progress : TextIO or None
        Where a line per run goes.

    Attributes
    ----------
    pendings : dict
        (seed, key) -> (run folder, its queued evaluations).
    walls, reused : dict
        ``seed<S>/<key>`` -> wall time of the runs run now / recorded by the runs reused.
    """

    def __init__(
        self,
        out: Path,
        evaluators: dict[int, Evaluator],
        points: int,
        held_out: Sequence[str],
        skip_existing: bool,
        progress: TextIO | None,
    ) -> None:
        self.out = out
        self.evaluators = evaluators
        self.points = points
        self.held_out = tuple(held_out)
        self.skip_existing = skip_existing
        self.progress = progress
        self.pendings: dict[tuple[int, str], tuple[Path, PendingRows]] = {}
        self.walls: dict[str, float] = {}
        self.reused: dict[str, float] = {}

    def here(self, configs: SeedConfigs) -> bool:
        """Run every one on this host, one after the other; False if any failed.

        Raises
        ------
        StudyInterrupted
            A run was interrupted.
        """
        ok = True
        for s, cfgs in configs.items():
            for key, cfg in cfgs:
                d = self._folder(s, cfg)
                if self._reuse(s, key, cfg, d):
                    continue
                self._say(
                    f"== {d.parent.name}/{cfg.name}: {len(cfg.robots)} robots, "
                    f"{cfg.iterations} iterations"
                )
                t0 = time.monotonic()
                done = run(cfg, d, progress=None, force=True)  # the study owns its folders
                self.walls[f"seed{s}/{key}"] = time.monotonic() - t0
                if done.interrupted:
                    raise StudyInterrupted(
                        f"{d.parent.name}/{cfg.name} interrupted ({done.interrupted})"
                    )
                ok = ok and done.ok
                self._queue(s, key, cfg, d)
        return ok

    def in_pool(self, configs: SeedConfigs, pool: Executor) -> list[Future]:
        """Submit every run as an in-process replica (:mod:`..fed_replicas`, bit-identical to
        a sync ``dfrl run``) to ``pool``; return the futures, in order. :meth:`collect` waits
        for them and queues their evaluations."""
        self._submitted: list[tuple[int, str, ExperimentConfig, Path, Future]] = []
        for s, cfgs in configs.items():
            for key, cfg in cfgs:
                d = self._folder(s, cfg)
                if self._reuse(s, key, cfg, d):
                    continue
                fut = pool.submit(replica_job, cfg.to_dict(), str(d))
                self._submitted.append((s, key, cfg, d, fut))
        return [f for *_, f in self._submitted]

    def collect(self, configs: SeedConfigs) -> bool:
        """Wait for the replicas :meth:`in_pool` submitted, queue each one's evaluations as it
        ends; True (a replica that fails raises)."""
        by_future = {f: (s, key, cfg, d) for s, key, cfg, d, f in self._submitted}
        for fut in as_completed(by_future):
            s, key, cfg, d = by_future[fut]
            self.walls[f"seed{s}/{key}"] = fut.result()["wall_time_s"]
            self._say(
                f"== {d.parent.name}/{cfg.name}: replica done in "
                f"{self.walls[f'seed{s}/{key}']:.0f} s"
            )
            self._queue(s, key, cfg, d)
        order = [(s, key) for s, cfgs in configs.items() for key, _ in cfgs]
        self.pendings = {k: self.pendings[k] for k in order if k in self.pendings}
        return True

    def on_cluster(self, configs: SeedConfigs, cluster: ClusterOptions) -> bool:
        """Run every one on ``cluster``, as many at once as it holds; False if any failed.

        Raises
        ------
        ExperimentError
            The cluster cannot be reached.
        StudyInterrupted
            A run was interrupted (the others are stopped).
        """
        where: dict[Path, tuple[int, str, ExperimentConfig]] = {}
        for s, cfgs in configs.items():
            for key, cfg in cfgs:
                d = self._folder(s, cfg)
                if not self._reuse(s, key, cfg, d):
                    where[d] = (s, key, cfg)
        if not where:
            return True
        at_once = runs_at_once(cluster, max(len(c.robots) for _, _, c in where.values()))
        self._say(f"== {len(where)} federated runs on cluster {cluster.address}, {at_once} at once")
        failed: list[str] = []

        def done(end: Finished) -> None:
            s, key, cfg = where[end.out]
            if end.exit in INTERRUPTED:
                raise StudyInterrupted(f"seed{s}/{cfg.name} was interrupted (exit {end.exit})")
            self.walls[f"seed{s}/{key}"] = end.wall
            if not end.ok:
                failed.append(f"seed{s}/{cfg.name}")
            if (end.out / "metrics.csv").is_file():
                self._queue(s, key, cfg, end.out)

        run_on_cluster(
            [(cfg, d) for d, (_, _, cfg) in where.items()], cluster, at_once, done, self.progress
        )
        # in the order of the configs, as here(): the report pairs runs by seed in this order
        order = [(s, key) for s, cfgs in configs.items() for key, _ in cfgs]
        self.pendings = {k: self.pendings[k] for k in order if k in self.pendings}
        if failed:
            self._say(f"== runs that FAILED on the cluster: {', '.join(failed)}")
        return not failed

    def _folder(self, seed: int, cfg: ExperimentConfig) -> Path:
        return self.out / f"seed{seed}" / cfg.name

    def _reuse(self, seed: int, key: str, cfg: ExperimentConfig, d: Path) -> bool:
        """Reuse a finished run (``skip_existing``); False if it must run."""
        if not (self.skip_existing and (d / "summary.md").is_file()):
            return False
        self.reused[f"seed{seed}/{key}"] = recorded_wall(d)
        self._queue(seed, key, cfg, d)
        return True

    def _queue(self, seed: int, key: str, cfg: ExperimentConfig, d: Path) -> None:
        """Queue the greedy evaluations of one run's table snapshots."""
        pending = PendingRows()
        arenas = {r.id: r.arena for r in cfg.robots}
        for robot, files in history_tables(d).items():
            its = pick(files, cfg.iterations, self.points)
            for it in its:  # the held-out arenas at the last point only (what T reads)
                pending.add(
                    self.evaluators[seed],
                    robot,
                    it,
                    np.load(files[it]),
                    arenas[robot],
                    self.held_out if it == its[-1] else (),
                )
        self.pendings[(seed, key)] = (d, pending)

    def _say(self, line: str) -> None:
        if self.progress is not None:
            print(line, file=self.progress, flush=True)
