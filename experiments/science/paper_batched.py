"""``dfrl paper --sim batched``: the paper's conditions on the batched simulator, judged by
the same questions.

Every run of every seed (the federated conditions of :func:`.reproduce.paper_configs`, the
standalone robots of :func:`.reproduce.standalone_plan`, the learning controls) is one group of
robots in a single :class:`~dfrl.robots.batched.training.BatchedTrainer`; the batch steps to the
next share of any federation, and each federation then folds its robots' tables with its
method (:data:`.studies.fedsim.AGGREGATIONS`, as the in-process replicas do) and writes the
aggregate back, the last share at the end of the budget. The final tables, the untrained and
the zero tables are evaluated in one compiled call, each robot in its own arena and the held-out
ones, with the evaluation seed of the seed, and the rows go through the questions as the
pybullet study's do (``evaluations.csv``, ``questions.csv``, ``contrasts_by_seed.csv``,
``report.md``). What it leaves out: curves and figures (no run folders), the evaluations before
the end (the questions read the last one), ``--driver`` and ``--cluster``.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from dfrl.experiments.provenance import write_provenance
from dfrl.experiments.science.fed_replicas import replica_trainer_configs
from dfrl.experiments.science.paper_confirm import confirm_paper, markdown
from dfrl.experiments.science.questions.answers import Answers
from dfrl.experiments.science.questions.catalogue import UNTRAINED
from dfrl.experiments.science.questions.evaluations import Evaluation
from dfrl.experiments.science.report.paper import write_questions_report
from dfrl.experiments.science.reproduce import (
    EVAL_SEED,
    HELD_OUT,
    ZERO_TABLE,
    PaperOptions,
    _judge,
    _seeds,
    _zeros,
    paper_configs,
    standalone_plan,
    untrained_table,
)
from dfrl.experiments.science.studies.confirm import Confirmation
from dfrl.experiments.science.studies.fedsim import AGGREGATIONS
from dfrl.experiments.science.studies.history import eval_many
from dfrl.experiments.science.studies.simulators import BATCHED
from dfrl.robots.batched.training import BatchedTrainer
from dfrl.robots.training import TrainerConfig


@dataclass
class Group:
    """Robots that learn together: a federation (``method``) or one standalone robot."""

    run: str
    seed: int
    robots: list[tuple[str, str]]  # (robot, arena), in itinerary order
    first: int  # index of the first robot in the batch
    iterations: int
    respite: int = 0  # 0: never shares
    method: str = ""


@dataclass
class BatchedPaper:
    """What :func:`batched_paper` produced."""

    report: Path
    answers: Answers
    total_s: float
    robots: int
    confirmation: list[Confirmation] = field(default_factory=list)


def _plan(opts: PaperOptions) -> tuple[list[Group], list[TrainerConfig]]:
    groups: list[Group] = []
    configs: list[TrainerConfig] = []
    for s in _seeds(opts):
        fed = paper_configs(opts, s)
        for run, cfg in fed:
            pairs = replica_trainer_configs(cfg, Path("."))
            groups.append(
                Group(
                    run,
                    s,
                    [(r.id, r.arena) for r, _ in pairs],
                    len(configs),
                    cfg.iterations,
                    cfg.respite,
                    cfg.method_for(pairs[0][0].algo),
                )
            )
            configs += [c for _, c in pairs]
        for run, _, tcfg in standalone_plan(opts, fed[0][1]):
            groups.append(Group(run, s, [(tcfg.arena, tcfg.arena)], len(configs), tcfg.iterations))
            configs.append(tcfg)
    return groups, configs


def _share(bt: BatchedTrainer, g: Group) -> None:
    idx = range(g.first, g.first + len(g.robots))
    table = AGGREGATIONS[g.method]([bt.q[i] for i in idx], [bt.visits[i] for i in idx])
    for i in idx:
        bt.set_table(i, table)


def _train(groups: list[Group], configs: list[TrainerConfig]) -> BatchedTrainer:
    iterations = {g.iterations for g in groups}
    if len(iterations) != 1:
        raise ValueError(f"one budget for every run of the batch, got {sorted(iterations)}")
    total = iterations.pop()
    stops = {total} | {k for g in groups if g.respite for k in range(g.respite, total, g.respite)}
    bt = BatchedTrainer(configs)
    done = 0
    for stop in sorted(stops):
        bt.run(stop - done)
        done = stop
        for g in groups:
            if g.respite and (stop % g.respite == 0 or stop == total):
                _share(bt, g)
    return bt


def _evaluations(opts: PaperOptions, groups: list[Group], bt: BatchedTrainer) -> list[Evaluation]:
    base = TrainerConfig().to_dict()
    shape = bt.q.shape[1:]
    jobs: list[tuple[str, int, str, str, int, str, np.ndarray]] = []
    for g in groups:
        for k, (robot, arena) in enumerate(g.robots):
            for where in (arena,) + HELD_OUT:
                jobs.append((g.run, g.seed, robot, arena, g.iterations, where, bt.q[g.first + k]))
    if opts.control:
        for s in _seeds(opts):
            own = dict.fromkeys(a for g in groups if g.seed == s and g.respite for _, a in g.robots)
            its = next(g.iterations for g in groups if g.seed == s)
            for run, make in ((UNTRAINED, untrained_table), (ZERO_TABLE, _zeros)):
                for a in own:
                    for where in (a,) + HELD_OUT:
                        jobs.append((run, s, a, a, its, where, make(s, a, shape)))
    scores = eval_many(
        base,
        [j[6] for j in jobs],
        [j[5] for j in jobs],
        opts.eval_steps,
        opts.episode_steps,
        [EVAL_SEED + j[1] for j in jobs],
        sim=BATCHED,
    )
    return [
        Evaluation(
            run,
            s,
            robot,
            arena,
            its,
            where,
            "own" if where == arena else "held_out",
            m["score"],
            m["collisions_per_1000"],
            m["progress"],
        )
        for (run, s, robot, arena, its, where, _), m in zip(jobs, scores)
    ]


def batched_paper(
    out: Path, opts: PaperOptions, progress: TextIO | None = None, confirm_seeds: int = 0
) -> BatchedPaper:
    """Run the paper's conditions on the batched simulator and judge the questions; with
    ``confirm_seeds`` K, confirm F and T on pybullet with the first K seeds
    (:mod:`.paper_confirm`).

    Raises
    ------
    ValueError
        Options the batched paper cannot run (``driver``, ``cluster``), or runs of different
        budgets.
    """
    if not 0 <= confirm_seeds <= len(_seeds(opts)):
        raise ValueError(
            f"--confirm-seeds {confirm_seeds}: between 0 and the study's {len(_seeds(opts))} seeds"
        )
    if opts.driver or opts.cluster is not None:
        raise ValueError("--sim batched runs every robot in one process: no --driver, no --cluster")
    t0 = time.monotonic()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_provenance(out)
    groups, configs = _plan(opts)
    if progress is not None:
        print(
            f"paper on the batched simulator: {len(groups)} runs, {len(configs)} robots",
            file=progress,
            flush=True,
        )
    bt = _train(groups, configs)
    evals = _evaluations(opts, groups, bt)
    ans = _judge(out, evals, opts)
    total = time.monotonic() - t0
    options: dict[str, Any] = {**asdict(opts), "sim": BATCHED}
    (out / "options.json").write_text(
        json.dumps(options, indent=2, default=str) + "\n", encoding="utf-8"
    )
    seeds = _seeds(opts)
    intro = [
        "# dFRL: the paper's questions on the batched simulator",
        "",
        f"Simulator: batched (`robots/batched`; pybullet is the reference: "
        f"`dfrl bench sim-fidelity`). Seeds {seeds[0]}..{seeds[-1]} ({len(seeds)}), "
        f"{len(groups)} runs of {configs[0].iterations:,} iterations per robot, "
        f"{len(configs)} robots in one batch, final tables evaluated {opts.eval_steps} "
        f"steps per arena; {total:.0f} s.",
    ]
    report = write_questions_report(
        out, ans, out, intro=intro, name="report.md", resamples=opts.resamples
    )
    confirmed: list[Confirmation] = []
    if confirm_seeds:
        confirmed = confirm_paper(out, opts, ans, confirm_seeds, progress)
        with open(report, "a", encoding="utf-8") as fh:
            fh.write("\n".join(markdown(confirmed, confirm_seeds)) + "\n")
    return BatchedPaper(report, ans, total, len(configs), confirmed)
