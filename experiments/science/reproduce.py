"""``dfrl paper``: the paper's experiment K times, greedy evaluations, a report of tests.

For every seed: the four federated combinations (Q-learning / SARSA x average / max, five
robots in R1..R5, ``experiments/configs/paper_*.json``, real robot processes and the
dFRL agent), the standalone baselines (each arena alone, the seed its federated robot has),
the negative controls, runs that cannot have learned, through the same pipeline (same seeds,
arenas and evaluations: :mod:`dfrl.experiments.science.report.observations`): the zero table
(never trained) and federated Q-learning/average and standalone Q-learning in every arena
trained on shuffled rewards (the ``reward_shuffle`` trainer option); and the off-policy
reference: federated Q-learning/average and standalone Q-learning in R1 and R4 with a random
behaviour policy (epsilon 1 throughout), which Q-learning learns from as well as from any other
behaviour, so it is no control. Each run's tables are evaluated at ``points`` evenly spaced
iterations (federated: the table history the robot processes write at every share;
standalone: snapshots) with the greedy policy in the robot's own arena and the held-out arenas
h1 and h2 (``evaluations.csv`` in the run's folder); the zero table once per seed, with that
seed's evaluation seed.

Layout of ``OUT``: ``seed<S>/<config name>/`` (a federated results folder, the controls'
``control_shuffled_qlearning_average`` and the reference's ``reference_qlearning_average``
among them), ``seed<S>/standalone/<algo>_<arena>/``,
``seed<S>/standalone/shuffled_qlearning_<arena>/``,
``seed<S>/standalone/reference_qlearning_<arena>/``, ``seed<S>/zero_table/evaluations.csv``,
``figures/`` (means over seeds with 95% bands), ``report.md``
(:mod:`dfrl.experiments.science.report.paper`), ``provenance.json`` (versions, commit, command
line: :mod:`dfrl.experiments.provenance`) and ``tidy.csv`` (every curve and evaluation, one
value per row: :mod:`dfrl.experiments.science.tidy`). Federated runs go one after another (each
uses both cores); standalone trainings and evaluations run meanwhile on a pool of ``jobs``
processes. SIGTERM or Ctrl-C stops the whole study (the current run stops cleanly, pending
jobs are cancelled); ``--skip-existing`` then reuses what finished.
"""
from __future__ import annotations

import signal
import sys
import threading
import time
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO
from collections.abc import Iterator

import numpy as np

from dfrl.experiments.driver.config import ExperimentConfig, resolve_config
from dfrl.experiments.driver.results.metrics import read_metrics
from dfrl.experiments.provenance import write_provenance
from dfrl.experiments.science.cluster_runs import ClusterOptions
from dfrl.experiments.science.paper_runs import FederatedRuns, StudyInterrupted  # noqa: F401
from dfrl.experiments.science.pool import stop_pool, study_pool
from dfrl.experiments.science.report.measures import SeedRun
from dfrl.experiments.science.report.observations import Controls
from dfrl.experiments.science.report.paper import write_report
from dfrl.experiments.science.report.stats import COMBOS
from dfrl.experiments.science.standalone import evaluated_job
from dfrl.experiments.science.studies.history import Evaluator, eval_job, read_rows, write_rows
from dfrl.experiments.science.tidy import TIDY_FILE, curve_rows, evaluation_rows, write_tidy
from dfrl.robots.state import Discretiser
from dfrl.robots.training import TrainerConfig, read_metrics_csv

#: Random behaviour: the off-policy reference's exploration schedule.
RANDOM_BEHAVIOUR = {"kind": "constant", "start": 1.0, "end": 1.0, "decay_steps": 1}
#: Held-out evaluation arenas.
HELD_OUT = ("h1", "h2")
#: Arenas of the off-policy reference's standalone runs.
REFERENCE_ARENAS = ("r1", "r4")
#: The shuffled-reward control's buffer (``reward_shuffle``): rewards a learnt reward is
#: drawn from, the smoothing window of the reward-per-step measures.
SHUFFLE_BUFFER = 1000
#: Default iterations per robot. 5 seeds of everything at 20,000 took 1,060 s (17.7 min) on
#: this 2-core machine shared with other test suites; at 15,000 the same wall time under a
#: heavier load, with 1,406 s of CPU (703 s if both cores were ours). See robots/README.md.
PAPER_ITERATIONS = 15_000
#: Evaluation seeds: this plus the training seed (the same for every configuration).
EVAL_SEED = 50_000


@dataclass(frozen=True)
class PaperOptions:
    """What ``dfrl paper`` runs (defaults: the 15-minute budget on two cores)."""

    seeds: int | tuple[int, ...] = 5    # a count (first_seed, first_seed + 1, ...) or the seeds
    first_seed: int = 1
    iterations: int | None = PAPER_ITERATIONS   # None: the configs' (20,000)
    respite: int | None = None
    points: int = 4                     # greedy evaluations per run
    eval_steps: int = 1000              # per table and arena
    episode_steps: int = 200
    jobs: int = 2
    control: bool = True                # the controls and the off-policy reference
    skip_existing: bool = False
    shuffle_buffer: int = SHUFFLE_BUFFER
    cluster: ClusterOptions | None = None   # federated runs' robots on a Dask cluster


@dataclass
class Reproduction:
    """What :func:`reproduce_paper` produced; ``ok``: every federated run succeeded."""

    report: Path
    fed: dict[str, list[SeedRun]]
    standalone: dict[str, list[SeedRun]]
    controls: Controls
    total_s: float
    ok: bool
    walls: dict[str, float] = field(default_factory=dict)
    seeds: list[int] = field(default_factory=list)
    reused: dict[str, float] = field(default_factory=dict)   # run -> its recorded wall time


def reference_learner() -> dict[str, Any]:
    """The learner settings of the off-policy reference: random behaviour throughout."""
    learner = TrainerConfig().to_dict()["learner"]
    learner["epsilon"] = dict(RANDOM_BEHAVIOUR)
    return learner


def paper_configs(opts: PaperOptions, seed: int) -> list[tuple[str, ExperimentConfig]]:
    """(key, config) of the federated runs of one seed; with ``opts.control`` the off-policy
    reference (key ``reference``) and the shuffled-reward control (``shuffled``) last."""
    changes: dict[str, Any] = {"seed": seed}
    if opts.iterations is not None:
        changes["iterations"] = opts.iterations
    if opts.respite is not None:
        changes["respite"] = opts.respite
    out = []
    for algo, method in COMBOS:
        cfg = ExperimentConfig.load(resolve_config(f"paper_{algo}_{method}")).replace(**changes)
        out.append((f"{algo}/{method}", cfg))
    if opts.control:
        base = ExperimentConfig.load(resolve_config("paper_qlearning_average")).replace(**changes)
        trainer = dict(base.trainer)
        trainer["learner"] = reference_learner()
        out.append(("reference", base.replace(
            name="reference_qlearning_average", trainer=trainer,
            title="off-policy reference: random behaviour (epsilon 1)")))
        out.append(("shuffled", base.replace(
            name="control_shuffled_qlearning_average",
            trainer={**base.trainer, "reward_shuffle": opts.shuffle_buffer},
            title=f"control: shuffled rewards (buffer {opts.shuffle_buffer})")))
    return out


def _raise_interrupt(signum: int, frame: Any) -> None:
    raise StudyInterrupted(f"signal {signum}")


def reproduce_paper(out: Path, opts: PaperOptions = PaperOptions(),
                    progress: TextIO | None = sys.stderr) -> Reproduction:
    """Run everything and write ``OUT/report.md`` and ``OUT/figures`` (progress lines to
    ``progress``).

    Raises
    ------
    ExperimentError
        A federated run could not be started.
    StudyInterrupted
        SIGTERM or Ctrl-C (SIGINT) stopped the study (handled when called from the main
        thread); finished runs stay in ``out``.
    """
    restore = []
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGTERM, signal.SIGINT):
            restore.append((sig, signal.signal(sig, _raise_interrupt)))
    try:
        return _reproduce(Path(out), opts, progress)
    finally:
        for sig, handler in restore:
            signal.signal(sig, handler)


def _reproduce(out: Path, opts: PaperOptions, progress: TextIO | None) -> Reproduction:
    out.mkdir(parents=True, exist_ok=True)
    write_provenance(out)
    t0 = time.monotonic()
    seeds = (list(opts.seeds) if isinstance(opts.seeds, tuple)
             else list(range(opts.first_seed, opts.first_seed + opts.seeds)))
    base_cfg = TrainerConfig().to_dict()
    fed_cfgs = {s: paper_configs(opts, s) for s in seeds}
    arenas = [r.arena for r in fed_cfgs[seeds[0]][0][1].robots]
    all_arenas = list(dict.fromkeys(arenas + list(HELD_OUT)))
    pool = study_pool(opts.jobs)
    try:
        n_states = Discretiser(TrainerConfig().discretisation).n_states
        n_actions = len(TrainerConfig().actions.names)
        zero = {a: pool.submit(eval_job, base_cfg, np.zeros((n_states, n_actions)), a, opts.eval_steps,
                               opts.episode_steps, EVAL_SEED) for a in all_arenas}
        sa_jobs: dict[tuple[int, str, str], Future] = {}
        zero_jobs: dict[int, dict[str, Future]] = {}
        for s in seeds:
            cfg0 = fed_cfgs[s][0][1]
            iters = cfg0.iterations
            for algo in ("qlearning", "sarsa"):
                for r in cfg0.robots:
                    sa_jobs[(s, algo, r.arena)] = _standalone(
                        pool, out / f"seed{s}" / "standalone" / f"{algo}_{r.arena}",
                        TrainerConfig(arena=r.arena, algo=algo, seed=cfg0.robot_seed(r),
                                      iterations=iters), opts, s)
            if opts.control:
                for r in cfg0.robots:
                    plain = TrainerConfig(arena=r.arena, seed=cfg0.robot_seed(r),
                                          iterations=iters)
                    sa_jobs[(s, "shuffled", r.arena)] = _standalone(
                        pool, out / f"seed{s}" / "standalone" / f"shuffled_qlearning_{r.arena}",
                        plain.replace(reward_shuffle=opts.shuffle_buffer), opts, s)
                    if r.arena in REFERENCE_ARENAS:
                        cfg = TrainerConfig.from_dict({**plain.to_dict(),
                                                       "learner": reference_learner()})
                        sa_jobs[(s, "reference", r.arena)] = _standalone(
                            pool, out / f"seed{s}" / "standalone"
                            / f"reference_qlearning_{r.arena}", cfg, opts, s)
                zero_jobs[s] = {a: pool.submit(eval_job, base_cfg, np.zeros((n_states, n_actions)),
                                               a, opts.eval_steps, opts.episode_steps,
                                               EVAL_SEED + s) for a in all_arenas}
        runs = FederatedRuns(out, {s: Evaluator(pool, base_cfg, opts.eval_steps,
                                                opts.episode_steps, EVAL_SEED + s)
                                   for s in seeds},
                             opts.points, HELD_OUT, opts.skip_existing, progress)
        ok = (runs.on_cluster(fed_cfgs, opts.cluster) if opts.cluster is not None
              else runs.here(fed_cfgs))
        pendings, walls, reused = runs.pendings, runs.walls, runs.reused
        for (s, key), (d, pending) in pendings.items():
            pending.write(d / "evaluations.csv")
        for fut in sa_jobs.values():
            fut.result()
        zero_score = {a: f.result()["score"] for a, f in zero.items()}
        for s, jobs in zero_jobs.items():
            _write_zero(out / f"seed{s}" / "zero_table", fed_cfgs[s][0][1], jobs)
    except BaseException:
        stop_pool(pool)
        raise
    pool.shutdown()
    fed: dict[str, list[SeedRun]] = {}
    controls = Controls()
    for (s, key), (d, _) in pendings.items():
        cfg = dict(fed_cfgs[s])[key]
        run = SeedRun(read_metrics(d / "metrics.csv"), {r.id: r.arena for r in cfg.robots},
                      read_rows(d / "evaluations.csv"), zero_score)
        into = {"reference": controls.reference_fed, "shuffled": controls.shuffled_fed}
        (into[key] if key in into else fed.setdefault(key, [])).append(run)
    standalone: dict[str, list[SeedRun]] = {}
    for s in seeds:
        if s in zero_jobs:
            rows = read_rows(out / f"seed{s}" / "zero_table" / "evaluations.csv")
            controls.zero.append(SeedRun({}, {r["robot"]: r["robot"] for r in rows}, rows,
                                         zero_score))
        for algo in ("qlearning", "sarsa", "shuffled", "reference"):
            keys = [k for k in sa_jobs if k[0] == s and k[1] == algo]
            if not keys:
                continue
            run = SeedRun({}, {}, [], zero_score)
            for k in keys:
                d = Path(sa_jobs[k].result())
                run.curves[k[2]] = read_metrics_csv(d / "metrics.csv")
                run.arenas[k[2]] = k[2]
                run.evals += read_rows(d / "evaluations.csv")
            into = {"reference": controls.reference_sa, "shuffled": controls.shuffled_sa}
            (into[algo] if algo in into else standalone.setdefault(algo, [])).append(run)
    total = time.monotonic() - t0
    rep = Reproduction(out / "report.md", fed, standalone, controls, total, ok, walls, seeds,
                       reused)
    write_tidy(out / TIDY_FILE, tidy_rows(rep))
    write_report(out, rep, opts, seeds)
    return rep


def tidy_rows(rep: Reproduction) -> Iterator[tuple]:
    """Every run's curves and evaluations as rows of ``tidy.csv``."""
    groups = [(k, "federated", v) for k, v in rep.fed.items()]
    groups += [(f"standalone/{k}", "standalone", v) for k, v in rep.standalone.items()]
    c = rep.controls
    groups += [("reference/qlearning/average", "reference federated", c.reference_fed),
               ("reference/standalone/qlearning", "reference standalone", c.reference_sa),
               ("control/shuffled/qlearning/average", "control shuffled federated",
                c.shuffled_fed),
               ("control/shuffled/standalone/qlearning", "control shuffled standalone",
                c.shuffled_sa),
               ("control/zero_table", "control zero table", c.zero)]
    for name, condition, runs in groups:
        for seed, r in zip(rep.seeds, runs):
            yield from curve_rows(name, seed, condition, r.curves)
            yield from evaluation_rows(name, seed, condition, r.evals)


def _write_zero(d: Path, cfg: ExperimentConfig, jobs: dict[str, Future]) -> None:
    """``d/evaluations.csv`` of the zero table: one robot per arena the federated robots learn
    in (robot = arena), its own arena and the held-out ones, at the budget's iteration (the
    table never changes)."""
    rows = []
    for arena in dict.fromkeys(r.arena for r in cfg.robots):
        for a, role in [(arena, "own")] + [(h, "held_out") for h in HELD_OUT]:
            rows.append({"robot": arena, "iteration": cfg.iterations, "arena": a, "role": role,
                         **jobs[a].result()})
    d.mkdir(parents=True, exist_ok=True)
    write_rows(d / "evaluations.csv", rows)


def _standalone(pool: ProcessPoolExecutor, d: Path, cfg: TrainerConfig, opts: PaperOptions,
                seed: int) -> Future:
    if opts.skip_existing and (d / "evaluations.csv").is_file():
        fut: Future = Future()
        fut.set_result(str(d))
        return fut
    return pool.submit(evaluated_job, cfg.to_dict(), str(d), opts.points, list(HELD_OUT),
                       opts.eval_steps, opts.episode_steps, EVAL_SEED + seed)
