"""``dfrl hetero``: does a dqn robot gain from a tabular peer in a grid federation, and the reverse?

**Design.** Per seed ``s``, four runs in the target arena (default R1), each robot's training
seed fixed by its role so that a robot is the same robot (initial weights, start and respawn
poses, exploration) in every run it takes part in:

* ``dqn_alone``: the dqn robot (seed ``1000 s``) on its own;
* ``ql_alone``: the Q-learning robot (seed ``1000 s + 1``) on its own;
* ``mixed``: both in one grid federation (:mod:`dfrl.robots.grid_view`): every ``respite``
  iterations (and after the last) the dqn's grid view and the Q-table are aggregated
  (``method``, default ``average``) and written back, the dqn absorbing it by distillation;
* ``ql_pair`` (control for the reverse question): the Q-learning robot with a second Q-learning
  robot (seed ``1000 s + 2``), the same federation with a tabular peer instead of the dqn.

The federation runs in one process (as :mod:`.fedsim`: robots stepped in turn, one sync round
of the agent at each boundary: read every table, aggregate, write back), with the same
:class:`~dfrl.robots.grid_view.GridView` the robot process registers in ``dfrl run``; a real
run of such a federation is tested in tests/experiments/test_hetero_run.py.

**Measures**, at every iteration of ``eval_at`` (after the share due then): the greedy
score ``progress - 0.05 x collisions/1000`` (robots/README.md) and the collisions per 1,000
steps of each robot's policy in the target arena, ``eval_steps`` steps in episodes of
``episode_steps`` from random poses, evaluation seed ``20,000 + s`` (the same episodes for
every run of a seed). **Comparisons**, paired by seed (:func:`..statistics.paired`, 95% t
intervals): dqn ``mixed - dqn_alone``, Q-learning ``mixed - ql_alone``, and the control
Q-learning ``ql_pair - ql_alone``. The dqn's distillation residuals (RMS, per share) are
reported too.

**Simulator** (``sim``): on pybullet every robot is a :class:`~dfrl.robots.training.Trainer`
(:func:`run_one`); on the batched simulator (the default) the Q-learning robots are batched
and the dqn robot stays on pybullet, the batched simulator having no dqn
(:mod:`.hetero_batched`); ``results.json`` records both (``sim``, ``simulators``).
"""

from __future__ import annotations

import hashlib
import json
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dfrl.experiments.science.statistics import Interval, paired
from dfrl.experiments.science.studies.fedsim import AGGREGATIONS
from dfrl.experiments.science.studies.simulators import BATCHED, DEFAULT_SIM, PYBULLET, check_sim

RUNS = ("dqn_alone", "ql_alone", "mixed", "ql_pair")
#: (role, algorithm, seed offset) of the robots of each run.
ROSTER: dict[str, tuple[tuple[str, str, int], ...]] = {
    "dqn_alone": (("dqn", "dqn", 0),),
    "ql_alone": (("ql", "qlearning", 1),),
    "mixed": (("dqn", "dqn", 0), ("ql", "qlearning", 1)),
    "ql_pair": (("ql", "qlearning", 1), ("ql2", "qlearning", 2)),
}
#: (role, run compared, baseline run) of the paired comparisons.
COMPARISONS = (
    ("dqn", "mixed", "dqn_alone"),
    ("ql", "mixed", "ql_alone"),
    ("ql", "ql_pair", "ql_alone"),
)
EVAL_SEED = 20_000


@dataclass(frozen=True)
class HeteroOptions:
    """What ``dfrl hetero`` runs (defaults: robots/README.md, "Heterogeneous federations")."""

    seeds: tuple[int, ...] = (1, 2, 3, 4, 5)
    arena: str = "r1"
    iterations: int = 8000
    respite: int = 500
    method: str = "average"
    eval_at: tuple[int, ...] = (2000, 4000, 8000)
    eval_steps: int = 1000
    episode_steps: int = 250
    jobs: int = 2
    sim: str = DEFAULT_SIM

    def check(self) -> None:
        """Raises ValueError naming the first bad option."""
        check_sim(self.sim)
        if len(self.seeds) < 2 or len(set(self.seeds)) != len(self.seeds) or min(self.seeds) < 0:
            raise ValueError(f"seeds: at least two distinct seeds >= 0, got {self.seeds}")
        if self.method not in AGGREGATIONS:
            raise ValueError(f"method: {self.method!r} is not one of {sorted(AGGREGATIONS)}")
        if self.iterations < 1 or self.respite < 1 or self.jobs < 1:
            raise ValueError("iterations, respite and jobs are >= 1")
        if not self.eval_at or any(not 0 < i <= self.iterations for i in self.eval_at):
            raise ValueError(f"eval_at: iterations in 1..{self.iterations}, got {self.eval_at}")
        if self.eval_steps < 1 or self.episode_steps < 1:
            raise ValueError("eval_steps and episode_steps are >= 1")


def trainer_config(algo: str, seed: int, options: HeteroOptions) -> Any:
    from dfrl.robots.training import TrainerConfig

    return TrainerConfig(arena=options.arena, algo=algo, seed=seed, iterations=options.iterations)


def score_policy(
    config: Any,
    seed: int,
    options: HeteroOptions,
    q_table: np.ndarray | None,
    params: np.ndarray | None,
) -> dict[str, float]:
    from dfrl.robots.evaluation import evaluate_policy

    r = evaluate_policy(
        config,
        "greedy",
        options.eval_steps,
        EVAL_SEED + seed,
        q_table=q_table,
        params=params,
        episode_steps=options.episode_steps,
    )
    return {
        "score": r.progress - 0.05 * r.collisions_per_1000,
        "collisions_per_1000": r.collisions_per_1000,
        "progress": r.progress,
    }


def share(views: list[Any], aggregate: Any, residuals: list[float]) -> None:
    """One share: every robot's table (a dqn's through its grid view) folded by ``aggregate``
    and written back; each grid view's distillation residual appended to ``residuals``."""
    from dfrl.robots.grid_view import GridView

    table = aggregate([v.q_table for v in views], [v.visits for v in views])
    for v in views:
        v.set_q_table(table)
        if isinstance(v, GridView):
            report = v.last_distillation
            assert report is not None, "a grid view's write distils"
            residuals.append(report.rms_after)


def run_one(run: str, seed: int, options: HeteroOptions) -> dict[str, Any]:
    """One run of one seed (see the module doc): its evaluation rows, the dqn's distillation
    residuals, the sha256 of each robot's final parameters (by role) and its wall time."""
    from dfrl.robots.grid_view import GridView
    from dfrl.robots.training import Trainer

    t0 = time.perf_counter()
    roster = ROSTER[run]
    trainers = [
        Trainer(trainer_config(algo, 1000 * seed + off, options)) for _, algo, off in roster
    ]
    views = [GridView(t) if t.learner_kind == "function" else t for t in trainers]
    rows: list[dict[str, Any]] = []
    residuals: list[float] = []
    aggregate = AGGREGATIONS[options.method]
    try:
        for i in range(1, options.iterations + 1):
            for t in trainers:
                t.step()
            if len(trainers) > 1 and (i % options.respite == 0 or i == options.iterations):
                share(views, aggregate, residuals)
            if i in options.eval_at:
                for (role, algo, _), t in zip(roster, trainers):
                    function = t.learner_kind == "function"
                    m = score_policy(
                        t.config,
                        seed,
                        options,
                        None if function else t.q_table.copy(),
                        t.params if function else None,
                    )
                    rows.append(
                        {
                            "seed": seed,
                            "run": run,
                            "role": role,
                            "algo": algo,
                            "sim": PYBULLET,
                            "iteration": i,
                            **m,
                        }
                    )
        digests = {
            role: hashlib.sha256(t.params.tobytes()).hexdigest()
            for (role, _, _), t in zip(roster, trainers)
        }
    finally:
        for t in trainers:
            t.close()
    return {
        "rows": rows,
        "residuals": residuals,
        "digests": digests,
        "seconds": time.perf_counter() - t0,
    }


def _job(args: tuple[str, int, HeteroOptions]) -> tuple[str, int, dict[str, Any]]:
    run, seed, options = args
    if options.sim == BATCHED:
        from dfrl.experiments.science.studies.hetero_batched import run_one_batched

        return run, seed, run_one_batched(run, seed, options)
    return run, seed, run_one(run, seed, options)


def simulators(sim: str) -> dict[str, str]:
    """The simulator of each learner of the study when it runs on ``sim`` (the batched one has
    no dqn: :mod:`.hetero_batched`)."""
    check_sim(sim)
    if sim == PYBULLET:
        return {"qlearning": PYBULLET, "dqn": PYBULLET}
    from dfrl.experiments.science.studies.hetero_batched import SIMULATORS

    return dict(SIMULATORS)


@dataclass(frozen=True)
class HeteroResults:
    """What :func:`run` found.

    Attributes
    ----------
    rows : list of dict
        One per (seed, run, robot role, evaluation iteration): the robot's ``sim``,
        ``score``, ``collisions_per_1000``, ``progress``.
    comparisons : list of dict
        Per comparison of :data:`COMPARISONS` and evaluation iteration: ``role``, ``run``,
        ``baseline``, ``iteration``, the paired ``score`` and ``collisions`` differences
        (mean, half width, n, p) and the two means.
    residuals : dict
        The dqn's distillation residual RMS over every share of the ``mixed`` runs: ``mean``,
        ``max``, ``shares``.
    digests : dict
        ``"RUN/SEED"`` -> role -> sha256 of that robot's final parameters.
    seconds : float
    sim : str
        The study's ``--sim``.
    simulators : dict
        Learner -> the simulator its robots ran on (with ``sim`` batched, the dqn's is
        pybullet).
    """

    rows: list[dict[str, Any]]
    comparisons: list[dict[str, Any]]
    residuals: dict[str, float]
    digests: dict[str, dict[str, str]]
    seconds: float
    sim: str = PYBULLET
    simulators: dict[str, str] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _interval(iv: Interval) -> dict[str, float]:
    return {"mean": iv.mean, "half": iv.half, "n": iv.n, "p": iv.p_value()}


def compare(
    rows: list[dict[str, Any]], seeds: tuple[int, ...], eval_at: tuple[int, ...]
) -> list[dict[str, Any]]:
    """The paired comparisons of :data:`COMPARISONS` at every evaluation iteration."""
    by = {(r["seed"], r["run"], r["role"], r["iteration"]): r for r in rows}
    out = []
    for role, run, base in COMPARISONS:
        for it in eval_at:
            a = [by[(s, run, role, it)] for s in seeds]
            b = [by[(s, base, role, it)] for s in seeds]
            entry: dict[str, Any] = {"role": role, "run": run, "baseline": base, "iteration": it}
            for key, name in (("score", "score"), ("collisions", "collisions_per_1000")):
                xa, xb = [r[name] for r in a], [r[name] for r in b]
                entry[key] = _interval(paired(xa, xb))
                entry[f"{key}_{run}"] = float(np.mean(xa))
                entry[f"{key}_{base}"] = float(np.mean(xb))
            out.append(entry)
    return out


def run(options: HeteroOptions, output_dir: str | Path | None = None) -> HeteroResults:
    """Every run of every seed (``options.jobs`` processes), the comparisons; with
    ``output_dir``, ``options.json``, ``rows.csv`` and ``results.json`` written there.

    Raises
    ------
    ValueError
        Bad options.
    """
    options.check()
    t0 = time.perf_counter()
    jobs = [(r, s, options) for s in options.seeds for r in RUNS]
    # the longest runs (the dqn's) first, so the two processes end together
    jobs.sort(key=lambda j: (j[0] not in ("mixed", "dqn_alone"), j[1]))
    if options.jobs == 1:
        done = [_job(j) for j in jobs]
    else:
        with ProcessPoolExecutor(options.jobs) as pool:
            done = list(pool.map(_job, jobs))
    rows = sorted(
        (row for _, _, res in done for row in res["rows"]),
        key=lambda r: (r["seed"], RUNS.index(r["run"]), r["role"], r["iteration"]),
    )
    res_rms = [x for run_name, _, res in done if run_name == "mixed" for x in res["residuals"]]
    results = HeteroResults(
        rows=rows,
        comparisons=compare(rows, options.seeds, options.eval_at),
        residuals={
            "mean": float(np.mean(res_rms)) if res_rms else float("nan"),
            "max": float(np.max(res_rms)) if res_rms else float("nan"),
            "shares": len(res_rms),
        },
        digests={f"{r}/{s}": res["digests"] for r, s, res in done},
        seconds=time.perf_counter() - t0,
        sim=options.sim,
        simulators=simulators(options.sim),
    )
    if output_dir is not None:
        out = Path(output_dir)
        out.mkdir(parents=True, exist_ok=True)
        (out / "options.json").write_text(
            json.dumps(asdict(options), indent=2) + "\n", encoding="utf-8"
        )
        fields = list(rows[0]) if rows else []
        lines = [",".join(fields)] + [
            ",".join(repr(r[f]) if isinstance(r[f], float) else str(r[f]) for f in fields)
            for r in rows
        ]
        (out / "rows.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")
        (out / "results.json").write_text(
            json.dumps(results.to_dict(), indent=2) + "\n", encoding="utf-8"
        )
    return results
