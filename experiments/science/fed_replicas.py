"""A paper federated run in one process: :func:`run_replica` runs a sync, chain-itinerary
config of tabular robots with :func:`dfrl.experiments.science.studies.fedsim.federate` instead
of robot processes and the dFRL agent, and writes the files of a driver run folder that
``dfrl paper`` reads.

Why it may: in sync mode a robot process serves the agent only at its respite boundaries
(``boundaries(iterations, respite)``, the last iteration included), one request at a time, and
goes on only once the round's table is written into it; between two boundaries it steps its
:class:`~dfrl.robots.training.Trainer` alone, seeded ``config.robot_seed(robot)`` with the
trainer config :meth:`~dfrl.experiments.robot_host.config.RobotConfig.trainer_config` builds.
The agent reads every table at the boundary, folds them in itinerary order (the config's robot
order) with the C vector maths and writes the aggregate, bit for bit (packed float64), into
every robot. :func:`federate` steps the same trainers in turn and folds the same tables in the
same order with the same element operations, so the two give the same tables, curves and
history (``tests/experiments/science/studies/test_fedsim_identity.py`` runs both and compares
them byte for byte).

What it writes into ``out`` (the driver's names and formats):

- ``config.json`` (the config resolved, without its token, as the driver writes it) and
  ``provenance.json``;
- ``metrics_<robot>.csv`` (a robot process's rows: iteration, ``repr`` of the sum of Q and of
  the cumulative reward, collisions) and ``metrics.csv`` merged from them
  (:func:`~dfrl.experiments.driver.results.metrics.merge_metrics`, the driver's own);
- ``shares_<robot>.csv``: one row per share (its round, the table's digest and sum), from
  which the merge marks ``metrics.csv``'s ``shared`` column;
- ``tables/history/<robot>_it<N>.npy``: the table after every share (N: the robot's
  iteration), what :func:`~dfrl.experiments.science.studies.history.history_tables` reads;
- ``tables/<robot>.npy`` + ``.json`` + ``.visits.npy``: the final table, as a robot saves it;
- ``summary.md`` with ``- wall time: X s`` (what
  :func:`~dfrl.experiments.science.paper_runs.recorded_wall` reads) and a line saying the run
  was replicated in one process.

No ``rounds.csv``, agent logs, checkpoints or plots: there is no agent.

Cost (``paper_qlearning_average``, 15,000 iterations, seed 1, this 2-core machine otherwise
quiet): the driver 21.2 s wall, 37.4 s CPU over both cores; a replica 28.4 s wall on one core
(28.4 s CPU), two replicas at once (a pool of 2) 30.4 s for both. Stepping the simulations is
most of it (``pybullet.stepSimulation`` about half), so a replica saves the processes, the
platform and the agent (about a quarter of the CPU), and two replicas side by side finish a run
every 15 s where the driver takes 21 s; under a load of 5 the driver took 46.8 s, a replica
72.9 s (it had half a core).
"""

from __future__ import annotations

import json
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

from dfrl.experiments.driver.config import ExperimentConfig, RobotSpec
from dfrl.experiments.driver.config_check import BUILTIN_METHODS
from dfrl.experiments.driver.results.files import claim_output
from dfrl.experiments.driver.results.metrics import merge_metrics
from dfrl.experiments.driver.results.tables import table_sum
from dfrl.experiments.provenance import describe, read_provenance, write_provenance
from dfrl.experiments.robot_host.checkpoint import save_learnt_atomically
from dfrl.experiments.robot_host.config import Mode, RobotConfig, boundaries
from dfrl.experiments.robot_host.files import METRIC_FIELDS, SHARE_FIELDS, CsvLog, share_row
from dfrl.experiments.science.studies.fedsim import AGGREGATIONS, federate
from dfrl.robots.learners import learner_kind
from dfrl.robots.training import StepMetrics, Trainer, TrainerConfig

__all__ = ["Replica", "replica_job", "replica_problems", "replica_trainer_configs", "run_replica"]

#: The line of ``summary.md`` that tells a replica from a driver run.
REPLICA_LINE = (
    "- replicated in one process (dfrl.experiments.science.fed_replicas): no robot "
    "processes, no agent; the same tables as a sync `dfrl run`"
)


@dataclass(frozen=True)
class Replica:
    """What :func:`run_replica` produced.

    Attributes
    ----------
    output_dir : Path
    config : ExperimentConfig
    wall_time_s : float
        Seconds from the first trainer built to the last file written.
    shares : int
        Shares (sync rounds) every robot received.
    ok : bool
        Always True (a failure raises); there for callers that also take driver
        :class:`~dfrl.experiments.driver.results.summary.Results`.
    interrupted : None
        Likewise (an interrupt raises :class:`KeyboardInterrupt`).
    """

    output_dir: Path
    config: ExperimentConfig
    wall_time_s: float
    shares: int
    ok: bool = True
    interrupted: str | None = None


def replica_problems(cfg: ExperimentConfig) -> list[str]:
    """Why ``cfg`` cannot be replicated in one process bit for bit (empty: it can)."""
    out = []
    if cfg.mode is not Mode.SYNC:
        out.append("mode: only sync runs are reproducible (async rounds follow wall time)")
    if cfg.joins:
        out.append("joins: robots that join during a run are not replicated")
    if cfg.itinerary != "chain":
        out.append(f"itinerary: {cfg.itinerary!r} folds in another order than a chain")
    if cfg.federation != "per_algorithm":
        out.append(f"federation: {cfg.federation!r} is not replicated")
    if cfg.eval_every:
        out.append("eval_every: live greedy evaluations are not replicated")
    if len(cfg.algorithms()) != 1:
        out.append(f"robots: one algorithm (one agent) only, got {cfg.algorithms()}")
    for algo in cfg.algorithms():
        if learner_kind(algo) != "tabular":
            out.append(f"robots: {algo!r} is not a tabular learner")
        method = cfg.method_for(algo)
        if method not in BUILTIN_METHODS or method not in AGGREGATIONS:
            out.append(f"method: {method!r} is not a built-in method of the agent")
    if cfg.remote_robots():
        out.append("robots: robots on other hosts are not replicated")
    return out


def replica_trainer_configs(
    cfg: ExperimentConfig, out: Path
) -> list[tuple[RobotSpec, TrainerConfig]]:
    """Each robot with the trainer config its robot process would build (seed
    ``cfg.robot_seed``, the config's ``trainer`` fields over the defaults)."""
    return [
        (
            r,
            RobotConfig(
                robot=r.id,
                out_dir=str(out),
                arena=r.arena,
                algo=r.algo,
                seed=cfg.robot_seed(r),
                iterations=cfg.iterations,
                respite=cfg.respite,
                mode=cfg.mode,
                trainer=dict(cfg.trainer),
            ).trainer_config(),
        )
        for r in cfg.robots
    ]


def run_replica(
    cfg: ExperimentConfig, out: str | Path, *, force: bool = False, progress: TextIO | None = None
) -> Replica:
    """Run ``cfg`` in this process and write its results folder (see the module's docs).

    Parameters
    ----------
    cfg : ExperimentConfig
        Sync, chain, one tabular algorithm, a built-in method, every robot spawned locally
        (:func:`replica_problems` says what else is refused).
    out : str or Path
        Results folder: created, or empty; a non-empty one is refused unless ``force``, which
        empties it first (a results folder only, as ``dfrl run``).
    force : bool
    progress : TextIO or None
        A line per share goes there (None: quiet).

    Raises
    ------
    ValueError
        ``cfg`` cannot be replicated (every reason in the message).
    FileExistsError
        ``out`` is not empty and ``force`` is not set.
    """
    problems = replica_problems(cfg)
    if problems:
        raise ValueError(f"{cfg.name}: cannot replicate in one process: " + "; ".join(problems))
    cfg.check()
    t0 = time.monotonic()
    out = claim_output(Path(out).resolve(), force)
    (out / "config.json").write_text(
        json.dumps(cfg.resolved().public_dict(), indent=2) + "\n", encoding="utf-8"
    )
    write_provenance(out)
    robots = replica_trainer_configs(cfg, out)
    ids = [r.id for r, _ in robots]
    history = out / "tables" / "history"
    history.mkdir(parents=True, exist_ok=True)
    logs = [CsvLog(out / f"metrics_{rid}.csv", METRIC_FIELDS) for rid in ids]
    share_logs = [CsvLog(out / f"shares_{rid}.csv", SHARE_FIELDS) for rid in ids]
    planned = boundaries(cfg.iterations, cfg.respite)
    shares = 0

    def on_step(k: int, m: StepMetrics) -> None:
        logs[k].row((ids[k], m.iteration, repr(m.q_sum), repr(m.cumulative_reward), m.collisions))

    def on_share(iteration: int, trainers: Sequence[Trainer]) -> None:
        nonlocal shares
        shares += 1
        for k, (rid, t) in enumerate(zip(ids, trainers)):
            _save_history(history, rid, iteration, t)
            share_logs[k].row(
                share_row(
                    rid, shares, iteration, t.q_table, {"round": shares}, float(t.q_table.sum())
                )
            )
        if iteration == cfg.iterations:  # the robots' final save
            for rid, t in zip(ids, trainers):
                save_learnt_atomically(t, out, rid)
        if progress is not None:
            print(
                f"{cfg.name}: share {shares}/{len(planned)} at iteration {iteration}",
                file=progress,
                flush=True,
            )

    try:
        federate(
            [c for _, c in robots],
            cfg.iterations,
            cfg.respite,
            cfg.method_for(robots[0][0].algo),
            on_step=on_step,
            on_share=on_share,
        )
    finally:
        for log in logs + share_logs:
            log.close()
    merge_metrics(out, ids)
    wall = time.monotonic() - t0
    _write_summary(out, cfg, wall, shares)
    return Replica(out, cfg, wall, shares)


def replica_job(cfg_dict: dict[str, Any], out: str, force: bool = True) -> dict[str, Any]:
    """:func:`run_replica` as a process-pool job (plain data in and out): the config's
    :meth:`~ExperimentConfig.to_dict`, the folder; returns ``{"out", "wall_time_s",
    "shares"}``."""
    rep = run_replica(ExperimentConfig.from_dict(cfg_dict), out, force=force)
    return {"out": str(rep.output_dir), "wall_time_s": rep.wall_time_s, "shares": rep.shares}


def _save_history(folder: Path, robot: str, iteration: int, trainer: Trainer) -> None:
    """``folder/<robot>_it<N>.npy``, as a robot process saves it at a share."""
    import numpy as np

    with open(folder / f"{robot}_it{iteration}.npy", "wb") as fh:
        np.save(fh, trainer.q_table)


def _write_summary(out: Path, cfg: ExperimentConfig, wall: float, shares: int) -> Path:
    """``summary.md``: the driver's first lines (wall time, mode, seed) and the final tables."""
    lines = [
        f"# {cfg.name}",
        "",
        cfg.default_title(),
        "",
        f"- wall time: {wall:.1f} s",
        f"- mode: {cfg.mode.value}, real-time factor: none (flat out)",
        f"- seed: {cfg.seed}; iterations {cfg.iterations}, respite {cfg.respite}, "
        f"rounds planned {cfg.rounds}, shares done {shares}",
        REPLICA_LINE,
    ]
    made_by = read_provenance(out)
    if made_by is not None:
        lines.append(f"- produced by {describe(made_by)} (provenance.json)")
    lines += [
        "",
        "| robot | arena | algo | seed | final sum of Q (tables/) |",
        "|---|---|---|---|---|",
    ]
    for r in cfg.robots:
        final = table_sum(out, r.id)
        q = "no table saved" if final is None else f"{final:.2f}"
        lines.append(f"| {r.id} | {r.arena} | {r.algo} | {cfg.robot_seed(r)} | {q} |")
    path = out / "summary.md"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path
