"""``dfrl transfer-study``: does a federated table transfer to unseen arenas better than the
right controls?

Source tables (per source seed, all Q-learning, ``iterations`` per robot):

* ``zeros``: no training;
* ``standalone``: one robot in R1 for ``iterations``;
* ``standalone_same_experience``: one robot in R1 for 5 x ``iterations`` (the federation's
  total experience);
* ``in_turn``: one robot in R1..R5 one after the other, ``iterations`` each;
* ``one_shot_average``: the element-wise mean of five independent standalone tables (R1..R5);
* ``federated_average``, ``federated_max``, ``federated_max_visited``: five robots in R1..R5
  sharing every ``respite`` iterations (:func:`dfrl.experiments.science.studies.fedsim.federate`).

Targets: the held-out arenas h1 (clutter of thin pillars) and h2 (loop corridor), never seen
in training, with ``target_seeds`` seeds each: the source table's greedy policy is evaluated
there (zero-shot score and collisions), and a robot starting from it learns ``fine_tune``
steps (collisions per 1,000 during them: what the paper's transfer claim is about). Per source
seed the target runs are averaged; intervals are over source seeds; each condition is also
compared with ``standalone`` paired by source seed (t interval of the paired differences).
"""
from __future__ import annotations

from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from typing import Any

import numpy as np

from dfrl.experiments.science.statistics import Interval, Outcome, interval, judge, paired
from dfrl.experiments.science.studies.fedsim import federate, in_turn
from dfrl.experiments.science.studies.history import eval_job
from dfrl.robots.training import Trainer, TrainerConfig

ARENAS = ("r1", "r2", "r3", "r4", "r5")
CONDITIONS = ("zeros", "standalone", "standalone_same_experience", "in_turn",
              "one_shot_average", "federated_average", "federated_max", "federated_max_visited")


@dataclass(frozen=True)
class StudyOptions:
    source_seeds: tuple[int, ...] = (1, 2, 3, 4, 5)
    target_seeds: tuple[int, ...] = (1, 2)
    targets: tuple[str, ...] = ("h1", "h2")
    iterations: int = 4000
    respite: int = 500
    fine_tune: int = 1000
    eval_steps: int = 1000
    episode_steps: int = 200
    jobs: int = 2


def source_job(condition: str, seed: int, opts: StudyOptions) -> tuple[str, int, np.ndarray]:
    """The source table of one condition and source seed (a worker job)."""
    n = opts.iterations
    cfg = lambda arena, k=0, it=n: TrainerConfig(arena=arena, seed=1000 * seed + k,  # noqa: E731
                                                 iterations=it)

    def alone(c: TrainerConfig) -> np.ndarray:
        with Trainer(c) as t:
            for _ in range(c.iterations):
                t.step()
            return t.q_table.copy()

    if condition == "zeros":
        with Trainer(cfg("r1")) as t:
            q = np.zeros_like(t.q_table)
    elif condition == "standalone":
        q = alone(cfg("r1"))
    elif condition == "standalone_same_experience":
        q = alone(cfg("r1", it=n * len(ARENAS)))
    elif condition == "in_turn":
        q = in_turn(cfg("r1"), ARENAS, n)
    elif condition == "one_shot_average":
        q = np.mean([alone(cfg(a, k)) for k, a in enumerate(ARENAS)], axis=0)
    elif condition.startswith("federated_"):
        q = federate([cfg(a, k) for k, a in enumerate(ARENAS)], n, opts.respite,
                     condition.removeprefix("federated_")).table
    else:
        raise ValueError(f"unknown condition {condition!r}")
    return condition, seed, q


def target_job(condition: str, seed: int, q: np.ndarray, arena: str, tseed: int,
               opts: StudyOptions) -> dict[str, Any]:
    """Zero-shot greedy evaluation and a fine-tuning run of one table in one target."""
    ev = eval_job(TrainerConfig().to_dict(), q, arena, opts.eval_steps, opts.episode_steps,
                  80_000 + tseed)
    with Trainer(TrainerConfig(arena=arena, seed=90_000 + tseed)) as t:
        t.set_q_table(q)
        for _ in range(opts.fine_tune):
            m = t.step()
    return {"condition": condition, "source_seed": seed, "arena": arena, "target_seed": tseed,
            "score": ev["score"], "eval_collisions_per_1000": ev["collisions_per_1000"],
            "progress": ev["progress"],
            "fine_tune_collisions_per_1000": 1000.0 * m.collisions / opts.fine_tune,
            "fine_tune_reward": m.cumulative_reward / opts.fine_tune,
            "table_min": float(q.min()), "table_sum": float(q.sum())}


MEASURES = ("score", "eval_collisions_per_1000", "fine_tune_collisions_per_1000",
            "fine_tune_reward", "table_min", "table_sum")


def transfer_study(opts: StudyOptions) -> list[dict[str, Any]]:
    """Every source table, then every target run; the target rows."""
    with ProcessPoolExecutor(max_workers=max(1, opts.jobs)) as pool:
        srcs = list(pool.map(source_job, *zip(*[(c, s, opts) for c in CONDITIONS
                                                 for s in opts.source_seeds])))
        args = [(c, s, q, a, t, opts) for c, s, q in srcs for a in opts.targets
                for t in opts.target_seeds]
        return list(pool.map(target_job, *zip(*args)))


def per_source(rows: Sequence[dict[str, Any]], condition: str, measure: str) -> list[float]:
    """One value per source seed: the mean over targets and target seeds."""
    seeds = sorted({r["source_seed"] for r in rows})
    return [float(np.mean([r[measure] for r in rows
                           if r["condition"] == condition and r["source_seed"] == s]))
            for s in seeds]


def summary(rows: Sequence[dict[str, Any]]) -> dict[str, dict[str, tuple[Interval, Interval]]]:
    """condition -> measure -> (interval, difference from ``standalone``, paired by source
    seed: every condition's sources are trained with the same seeds)."""
    return {c: {m: (interval(per_source(rows, c, m)),
                    paired(per_source(rows, c, m), per_source(rows, "standalone", m)))
                for m in MEASURES} for c in CONDITIONS}


def markdown(rows: Sequence[dict[str, Any]], opts: StudyOptions) -> str:
    s = summary(rows)
    L = [f"Sources: {len(opts.source_seeds)} seeds, {opts.iterations} iterations per robot "
         f"(federations share every {opts.respite}). Targets: {', '.join(opts.targets)} x "
         f"{len(opts.target_seeds)} seeds; zero-shot greedy evaluation ({opts.eval_steps} steps) "
         f"and {opts.fine_tune} steps of learning from the table. Mean ± 95% t half width over "
         "source seeds; Δ: difference from `standalone`, paired by source seed.", "",
         "| source table | zero-shot score | Δ score | zero-shot collisions/1000 | "
         "collisions/1000 while learning | Δ collisions while learning | reward/step while "
         "learning | table min | table sum |", "|---|---|---|---|---|---|---|---|---|"]
    for c in CONDITIONS:
        m = s[c]
        L.append(f"| {c} | {m['score'][0]} | {m['score'][1]} | "
                 f"{m['eval_collisions_per_1000'][0]} | {m['fine_tune_collisions_per_1000'][0]} | "
                 f"{m['fine_tune_collisions_per_1000'][1]} | {m['fine_tune_reward'][0]} | "
                 f"{m['table_min'][0]} | {m['table_sum'][0]} |")
    L += ["", verdict(rows)]
    return "\n".join(L)


def verdict(rows: Sequence[dict[str, Any]]) -> str:
    """The paper's claim (federated tables transfer better) in the verdict words of
    :func:`dfrl.experiments.science.statistics.judge`."""
    d = {c: judge(paired(per_source(rows, "federated_average", "score"),
                         per_source(rows, c, "score")))
         for c in ("standalone", "standalone_same_experience", "in_turn", "one_shot_average")}
    held = {c: j.outcome is Outcome.HOLDS for c, j in d.items()}
    L = ["**Verdict on the paper's claim** (a federated table transfers to new arenas). "
         "Zero-shot greedy score on the unseen arenas, federated average minus (paired by "
         "source seed; the claim is that the difference is above 0):"]
    for c, j in d.items():
        L.append(f"{c}: Δ {j.measure}, {j.words()};")
    if held["standalone"] and not (held["in_turn"] or held["one_shot_average"]):
        L.append("So the federated table transfers better than a standalone one, but not "
                 "significantly better than one robot that saw the same arenas in turn or a "
                 "one-shot average: the diversity of arenas may be what helps, not federation.")
    elif held["standalone"]:
        L.append("So federation helps transfer, beyond the diversity of its arenas.")
    else:
        L.append(f"So the claim is {d['standalone'].words()} against a standalone table.")
    return " ".join(L)
