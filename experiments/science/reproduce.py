"""``dfrl paper``: the paper's experiment K times, greedy evaluations, the questions judged.

For every seed (:func:`paper_configs`, :func:`standalone_plan`): the federated conditions
(Q-learning / SARSA x average / max and Q-learning / visit_average, five robots in R1..R5,
``experiments/configs/paper_*.json``), the standalone conditions (each arena alone, with the
seed its federated robot has), the learning controls, runs that cannot learn what question L
asks, through the same pipeline (federated average and standalone of each algorithm trained with
the control's rewards, the ``reward_shuffle`` trainer option), the untrained tables (seeded
random values, never trained: :func:`untrained_table`), the all-zero table (a diagnostic), and
with ``diagnostics`` the off-policy reference (Q-learning with random behaviour, epsilon 1,
which Q-learning learns from as from any other behaviour: no control, a diagnostic). Each run's
tables are evaluated at ``points`` evenly spaced iterations (federated: the table history the
robot processes write at every share; standalone: snapshots) with the greedy policy in the
robot's own arena, and at the last one in the held-out arenas h1 and h2 too, with the seed's
evaluation episodes (the same for every condition of a seed); the untrained and zero tables once
per seed and arena.

Layout of ``OUT``: ``seed<S>/<config name>/`` (a federated results folder),
``seed<S>/standalone/<algo>_<arena>/`` (``control_<algo>_<arena>``,
``reference_qlearning_<arena>``), ``seed<S>/untrained/evaluations.csv`` (the untrained tables:
:func:`untrained_table`), ``seed<S>/zero_table/evaluations.csv`` (a diagnostic),
``evaluations.csv`` (every evaluation of the study, one row each:
:mod:`dfrl.experiments.science.questions.evaluations`), ``questions.csv`` and
``contrasts_by_seed.csv`` (every number a verdict uses), ``figures/``, ``report.md``
(:mod:`dfrl.experiments.science.report.paper`), ``provenance.json`` and ``tidy.csv`` (every
curve and evaluation, one value per row).

**Which runs use which.** Every federated run is by
default an in-process replica (:mod:`.fed_replicas`: the same trainers, seeds, share boundaries
and folds as a sync ``dfrl run``, bit-identical in tables, curves and history, which
``tests/experiments/science/studies/test_fedsim_identity.py`` checks for every config this
module makes), on the pool of ``jobs`` processes beside the standalone trainings and the
evaluations; with ``driver`` (``--driver``) each goes through ``dfrl run`` (robot processes, the
platform and the dFRL agent) one after another, and with ``cluster`` on a Dask cluster. SIGTERM
or Ctrl-C stops the whole study (the current run stops cleanly, pending jobs are cancelled);
``--skip-existing`` then reuses what finished. :func:`rejudge` judges a study's folder again
from its ``evaluations.csv`` without running anything (``dfrl paper --from``).
"""

from __future__ import annotations

import signal
import sys
import threading
import time
import zlib
from collections.abc import Iterator, Mapping
from concurrent.futures import Future, ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from dfrl.experiments.driver.config import ExperimentConfig, resolve_config
from dfrl.experiments.driver.results.metrics import read_metrics
from dfrl.experiments.provenance import write_provenance
from dfrl.experiments.science.cluster_runs import ClusterOptions
from dfrl.experiments.science.paper_runs import FederatedRuns, StudyInterrupted  # noqa: F401
from dfrl.experiments.science.pool import stop_pool, study_pool
from dfrl.experiments.science.questions.answers import Answers, answer
from dfrl.experiments.science.questions.catalogue import CONTROL, REFERENCE, UNTRAINED
from dfrl.experiments.science.questions.evaluations import (
    EVALUATIONS_FILE,
    Evaluation,
    from_rows,
    read_evaluations,
    write_evaluations,
)
from dfrl.experiments.science.questions.report import write_files
from dfrl.experiments.science.report.measures import SeedRun
from dfrl.experiments.science.report.paper import write_questions_report, write_report
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
#: The learning control's buffer (``reward_shuffle``).
SHUFFLE_BUFFER = 1000
#: Default iterations per robot: 10,000 keeps five seeds of every condition within 15 minutes
#: on two cores (at 15,000 with 4 evaluation points a run took 22 minutes, 2,558 s of CPU;
#: experiments/science/README.md, "Questions", gives both).
PAPER_ITERATIONS = 10_000
#: Evaluation seeds: this plus the study seed (the same for every condition of a seed).
EVAL_SEED = 50_000
#: The untrained tables' generator seed (with the study seed and the arena).
UNTRAINED_SEED = 70_707
#: The all-zero table's condition (a diagnostic: greedy with random ties, a random walk).
ZERO_TABLE = "reference/zero_table"
#: The algorithms, and the federated conditions (algo, method) of every seed.
ALGOS = ("qlearning", "sarsa")
FEDERATED = (
    ("qlearning", "average"),
    ("qlearning", "max"),
    ("qlearning", "visit_average"),
    ("sarsa", "average"),
    ("sarsa", "max"),
)


@dataclass(frozen=True)
class PaperOptions:
    """What ``dfrl paper`` runs (defaults: the 15-minute budget on two cores)."""

    seeds: int | tuple[int, ...] = 5  # a count (first_seed, first_seed + 1, ...) or the seeds
    first_seed: int = 1
    iterations: int | None = PAPER_ITERATIONS  # None: the configs' (20,000)
    respite: int | None = None
    points: int = 2  # greedy evaluations per run (held-out: the last)
    eval_steps: int = 1000  # per table and arena
    episode_steps: int = 200
    jobs: int = 2
    control: bool = True  # the learning controls and the untrained table
    driver: bool = False  # federated runs through `dfrl run`, not replicas
    diagnostics: bool = False  # the off-policy reference (epsilon 1)
    skip_existing: bool = False
    shuffle_buffer: int = SHUFFLE_BUFFER
    deltas: tuple[tuple[str, float], ...] = ()  # question -> smallest effect of interest
    cluster: ClusterOptions | None = None  # federated runs' robots on a Dask cluster
    resamples: int = 2000  # of the rliable intervals in the report's aggregates


@dataclass
class Reproduction:
    """What :func:`reproduce_paper` produced; ``ok``: every federated run succeeded.

    ``runs``: condition -> one :class:`SeedRun` per seed, in the order of ``seeds`` (a
    standalone condition's SeedRun holds every arena's robot; the untrained table's has
    evaluations only)."""

    report: Path
    runs: dict[str, list[SeedRun]]
    answers: Answers
    total_s: float
    ok: bool
    walls: dict[str, float] = field(default_factory=dict)
    seeds: list[int] = field(default_factory=list)
    reused: dict[str, float] = field(default_factory=dict)  # run -> its recorded wall time


def reference_learner() -> dict[str, Any]:
    """The learner settings of the off-policy reference: random behaviour throughout."""
    learner = TrainerConfig().to_dict()["learner"]
    learner["epsilon"] = dict(RANDOM_BEHAVIOUR)
    return learner


def control_trainer(trainer: Mapping[str, Any], opts: PaperOptions) -> dict[str, Any]:
    """A trainer configuration turned into the learning control's."""
    return {**trainer, "reward_shuffle": opts.shuffle_buffer}


def paper_configs(opts: PaperOptions, seed: int) -> list[tuple[str, ExperimentConfig]]:
    """(condition, config) of the federated runs of one seed: :data:`FEDERATED`, then with
    ``opts.control`` each algorithm's control (``control/<algo>/average``), with
    ``opts.diagnostics`` the off-policy reference (``reference/qlearning/average``)."""
    changes: dict[str, Any] = {"seed": seed}
    if opts.iterations is not None:
        changes["iterations"] = opts.iterations
    if opts.respite is not None:
        changes["respite"] = opts.respite

    def base(algo: str) -> ExperimentConfig:
        return ExperimentConfig.load(resolve_config(f"paper_{algo}_average")).replace(**changes)

    out = []
    for algo, method in FEDERATED:
        if method in ("average", "max"):
            cfg = ExperimentConfig.load(resolve_config(f"paper_{algo}_{method}"))
            out.append((f"{algo}/{method}", cfg.replace(**changes)))
        else:
            out.append(
                (
                    f"{algo}/{method}",
                    base(algo).replace(
                        name=f"paper_{algo}_{method}",
                        method=method,
                        title=f"paper: 5 robots in R1..R5, {algo}, {method}",
                    ),
                )
            )
    if opts.control:
        for algo in ALGOS:
            b = base(algo)
            out.append(
                (
                    f"{CONTROL}{algo}/average",
                    b.replace(
                        name=f"control_{algo}_average",
                        trainer=control_trainer(b.trainer, opts),
                        title=f"learning control: {algo}, average, control rewards",
                    ),
                )
            )
    if opts.diagnostics:
        b = base("qlearning")
        trainer = {**b.trainer, "learner": reference_learner()}
        out.append(
            (
                f"{REFERENCE}qlearning/average",
                b.replace(
                    name="reference_qlearning_average",
                    trainer=trainer,
                    title="off-policy reference: random behaviour (epsilon 1)",
                ),
            )
        )
    return out


def standalone_plan(
    opts: PaperOptions,
    cfg: ExperimentConfig,
) -> list[tuple[str, str, TrainerConfig]]:
    """(condition, folder name, trainer config) of one seed's standalone runs: each arena of
    ``cfg``'s robots alone with its robot's training seed."""
    out = []
    for r in cfg.robots:
        for algo in ALGOS:
            plain = TrainerConfig(
                arena=r.arena, algo=algo, seed=cfg.robot_seed(r), iterations=cfg.iterations
            )
            out.append((f"standalone/{algo}", f"{algo}_{r.arena}", plain))
            if opts.control:
                ctrl = TrainerConfig.from_dict(control_trainer(plain.to_dict(), opts))
                out.append((f"{CONTROL}standalone/{algo}", f"control_{algo}_{r.arena}", ctrl))
        if opts.diagnostics and r.arena in REFERENCE_ARENAS:
            ref = TrainerConfig(arena=r.arena, seed=cfg.robot_seed(r), iterations=cfg.iterations)
            ref = TrainerConfig.from_dict({**ref.to_dict(), "learner": reference_learner()})
            out.append((f"{REFERENCE}standalone/qlearning", f"reference_qlearning_{r.arena}", ref))
    return out


def _raise_interrupt(signum: int, frame: Any) -> None:
    raise StudyInterrupted(f"signal {signum}")


def reproduce_paper(
    out: Path, opts: PaperOptions = PaperOptions(), progress: TextIO | None = sys.stderr
) -> Reproduction:
    """Run everything and write ``OUT/report.md``, the questions' files and ``OUT/figures``
    (progress lines to ``progress``).

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


def _seeds(opts: PaperOptions) -> list[int]:
    return (
        list(opts.seeds)
        if isinstance(opts.seeds, tuple)
        else list(range(opts.first_seed, opts.first_seed + opts.seeds))
    )


def _reproduce(out: Path, opts: PaperOptions, progress: TextIO | None) -> Reproduction:
    out.mkdir(parents=True, exist_ok=True)
    write_provenance(out)
    t0 = time.monotonic()
    seeds = _seeds(opts)
    base_cfg = TrainerConfig().to_dict()
    fed_cfgs = {s: paper_configs(opts, s) for s in seeds}
    pool = study_pool(opts.jobs)
    try:
        n_states = Discretiser(TrainerConfig().discretisation).n_states
        shape = (n_states, len(TrainerConfig().actions.names))
        runs = FederatedRuns(
            out,
            {
                s: Evaluator(pool, base_cfg, opts.eval_steps, opts.episode_steps, EVAL_SEED + s)
                for s in seeds
            },
            opts.points,
            HELD_OUT,
            opts.skip_existing,
            progress,
        )
        replicas = opts.cluster is None and not opts.driver
        if replicas:  # the longest jobs first
            runs.in_pool(fed_cfgs, pool)
        sa_jobs: dict[tuple[int, str, str], Future] = {}
        fixed_jobs: dict[tuple[int, str], dict[tuple[str, str], Future]] = {}
        for s in seeds:
            cfg0 = fed_cfgs[s][0][1]
            for run, name, tcfg in standalone_plan(opts, cfg0):
                sa_jobs[(s, run, tcfg.arena)] = _standalone(
                    pool, out / f"seed{s}" / "standalone" / name, tcfg, opts, s
                )
            if opts.control:
                for run, table in ((UNTRAINED, untrained_table), (ZERO_TABLE, _zeros)):
                    fixed_jobs[(s, run)] = {
                        (a, b): pool.submit(
                            eval_job,
                            base_cfg,
                            table(s, a, shape),
                            b,
                            opts.eval_steps,
                            opts.episode_steps,
                            EVAL_SEED + s,
                        )
                        for a in dict.fromkeys(r.arena for r in cfg0.robots)
                        for b in (a,) + HELD_OUT
                    }
        if replicas:
            ok = runs.collect(fed_cfgs)
        elif opts.cluster is not None:
            ok = runs.on_cluster(fed_cfgs, opts.cluster)
        else:
            ok = runs.here(fed_cfgs)
        for d, pending in runs.pendings.values():
            pending.write(d / "evaluations.csv")
        for fut in sa_jobs.values():
            fut.result()
        for (s, run), jobs in fixed_jobs.items():
            _write_fixed(out / f"seed{s}" / run.split("/")[-1], fed_cfgs[s][0][1], jobs)
    except BaseException:
        stop_pool(pool)
        raise
    pool.shutdown()
    by_run: dict[str, list[SeedRun]] = {}
    evals: list[Evaluation] = []
    for (s, key), (d, _) in runs.pendings.items():
        cfg = dict(fed_cfgs[s])[key]
        arenas = {r.id: r.arena for r in cfg.robots}
        got = SeedRun(read_metrics(d / "metrics.csv"), arenas, read_rows(d / "evaluations.csv"))
        by_run.setdefault(key, []).append(got)
        evals += from_rows(key, s, got.evals, arenas)
    for s in seeds:
        for name in dict.fromkeys(k[1] for k in sa_jobs if k[0] == s):
            got = SeedRun({}, {}, [])
            for k in (k for k in sa_jobs if k[0] == s and k[1] == name):
                d = Path(sa_jobs[k].result())
                got.curves[k[2]] = read_metrics_csv(d / "metrics.csv")
                got.arenas[k[2]] = k[2]
                got.evals += read_rows(d / "evaluations.csv")
            by_run.setdefault(name, []).append(got)
            evals += from_rows(name, s, got.evals)
        for run in (r for (t, r) in fixed_jobs if t == s):
            rows = read_rows(out / f"seed{s}" / run.split("/")[-1] / "evaluations.csv")
            by_run.setdefault(run, []).append(
                SeedRun({}, {r["robot"]: r["robot"] for r in rows}, rows)
            )
            evals += from_rows(run, s, rows)
    ans = _judge(out, evals, opts)
    rep = Reproduction(
        out / "report.md", by_run, ans, time.monotonic() - t0, ok, runs.walls, seeds, runs.reused
    )
    write_tidy(out / TIDY_FILE, tidy_rows(rep))
    write_report(out, rep, opts, seeds)
    return rep


def _judge(out: Path, evals: list[Evaluation], opts: PaperOptions) -> Answers:
    """Write ``evaluations.csv``, judge the questions, write their files."""
    write_evaluations(out / EVALUATIONS_FILE, evals)
    ans = answer(evals, dict(opts.deltas))
    write_files(out, ans)
    return ans


def rejudge(
    folder: Path,
    deltas: Mapping[str, float] | None = None,
    out: Path | None = None,
    resamples: int = 2000,
) -> tuple[Answers, Path]:
    """Judge a study's questions again from ``folder/evaluations.csv``, running nothing;
    write ``questions.csv``, ``contrasts_by_seed.csv`` and ``questions.md`` into ``out``
    (default: ``folder``). Returns the answers and the report's path.

    Raises
    ------
    EvaluationsError
        A row that cannot be read (file and line named).
    OSError
        No ``evaluations.csv`` in ``folder``.
    """
    evals = read_evaluations(Path(folder) / EVALUATIONS_FILE)
    ans = answer(evals, deltas)
    dest = Path(out) if out is not None else Path(folder)
    dest.mkdir(parents=True, exist_ok=True)
    write_files(dest, ans)
    return ans, write_questions_report(dest, ans, Path(folder), resamples=resamples)


#: The condition column of ``tidy.csv`` for a run name.
def condition_of(run: str) -> str:
    if run == UNTRAINED:
        return "untrained"
    if run == ZERO_TABLE:
        return "reference zero table"
    kind = "standalone" if "standalone/" in run else "federated"
    if run.startswith(CONTROL):
        return f"control {kind}"
    if run.startswith(REFERENCE):
        return f"reference {kind}"
    return kind


def tidy_rows(rep: Reproduction) -> Iterator[tuple]:
    """Every run's curves and evaluations as rows of ``tidy.csv``."""
    for name, runs in rep.runs.items():
        for seed, r in zip(rep.seeds, runs):
            yield from curve_rows(name, seed, condition_of(name), r.curves)
            yield from evaluation_rows(name, seed, condition_of(name), r.evals)


def untrained_table(seed: int, arena: str, shape: tuple[int, int]) -> np.ndarray:
    """The untrained table of ``arena`` in study seed ``seed``: uniform random values, never
    trained, seeded by (:data:`UNTRAINED_SEED`, seed, the arena's CRC-32). Its greedy policy
    is a fixed arbitrary one, as every trained or control table's is (the all-zero table breaks
    its ties at random at every step instead: a random walk, which collides more than any
    fixed policy; robots/README.md, "Controls")."""
    return np.random.default_rng([UNTRAINED_SEED, seed, zlib.crc32(arena.encode())]).random(shape)


def _zeros(seed: int, arena: str, shape: tuple[int, int]) -> np.ndarray:
    return np.zeros(shape)


def _write_fixed(d: Path, cfg: ExperimentConfig, jobs: Mapping[tuple[str, str], Future]) -> None:
    """``d/evaluations.csv`` of a table that is never trained: one robot per arena the
    federated robots learn in (robot = arena), in its own arena and the held-out ones, at the
    budget's iteration."""
    rows = [
        {
            "robot": a,
            "iteration": cfg.iterations,
            "arena": b,
            "role": "own" if a == b else "held_out",
            **fut.result(),
        }
        for (a, b), fut in jobs.items()
    ]
    d.mkdir(parents=True, exist_ok=True)
    write_rows(d / "evaluations.csv", rows)


def _standalone(
    pool: ProcessPoolExecutor, d: Path, cfg: TrainerConfig, opts: PaperOptions, seed: int
) -> Future:
    if opts.skip_existing and (d / "evaluations.csv").is_file():
        fut: Future = Future()
        fut.set_result(str(d))
        return fut
    return pool.submit(
        evaluated_job,
        cfg.to_dict(),
        str(d),
        opts.points,
        list(HELD_OUT),
        opts.eval_steps,
        opts.episode_steps,
        EVAL_SEED + seed,
    )
