"""Question L on real training and real evaluations (small budgets), judged through
``dfrl paper --from``: fed a clearly learnt run, L holds; fed non-learners as its "real" runs
(the all-zero table, a uniform random policy, an untrained random table), no L contrast holds;
the learning control's check includes 0.

Budget chosen by measurement: standalone Q-learning, arenas R1 and R2, 10,000 iterations,
seeds 1-5, the trained and the control tables learnt in the batched simulator (2 s for the 20,
where training them in pybullet took the suite 4 minutes; robots/README.md, "The batched
simulator"), every table evaluated in pybullet: greedy evaluations of 400 steps in episodes of
100 in the own arena and h1, the evaluation seed 50,000 + seed as ``dfrl paper`` evaluates.
Own-arena scores measured (R1/R2 per seed): 0.64/0.84, 0.76/0.78, 0.73/0.82, 0.76/0.00,
0.76/0.87 (the control's: -0.27 to 0.66, eight of ten at or below 0): a standalone robot
sometimes settles on turning in place (score 0), which is why the learner is judged on the mean
over arenas and seeds, not on one run.
"""

from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from dfrl.experiments.science.questions.evaluations import Evaluation, write_evaluations
from dfrl.experiments.science.reproduce import (
    EVAL_SEED,
    PaperOptions,
    control_trainer,
    untrained_table,
)
from dfrl.experiments.science.studies.history import COLLISION_COST
from dfrl.robots.evaluation import PolicyKind, evaluate_policy
from dfrl.robots.batched.training import BatchedTrainer
from dfrl.robots.training import TrainerConfig

SEEDS = (1, 2, 3, 4, 5)
ARENAS = ("r1", "r2")
ITERATIONS = 10_000
STEPS, EPISODE = 400, 100
KINDS = ("trained", "control", "untrained", "zeros", "random", "untrained2")


def _configs(kind: str, seed: int, arena: str) -> TrainerConfig:
    cfg = TrainerConfig(arena=arena, seed=1000 * seed, iterations=ITERATIONS)
    if kind == "control":
        return TrainerConfig.from_dict(control_trainer(cfg.to_dict(), PaperOptions()))
    return cfg


def _learnt() -> dict[tuple[str, int, str], np.ndarray]:
    """The trained and control tables, learnt together in the batched simulator (seconds,
    where 20 pybullet runs took minutes; evaluated in pybullet below)."""
    keys = [(k, s, a) for k in ("trained", "control") for s in SEEDS for a in ARENAS]
    trainer = BatchedTrainer([_configs(*key) for key in keys])
    trainer.run(ITERATIONS)
    return {key: trainer.q[i].copy() for i, key in enumerate(keys)}


def _evaluations(kind: str, seed: int, arena: str, q: np.ndarray | None) -> list[tuple]:
    cfg = _configs("trained", seed, arena)
    if kind == "untrained":
        q = untrained_table(seed, arena, (81, 3))
    elif kind == "untrained2":  # another untrained table: a non-learner fed as real
        q = untrained_table(seed + 100, arena, (81, 3))
    elif q is None:
        q = np.zeros((81, 3))
    out = []
    for where, role in ((arena, "own"), ("h1", "held_out")):
        r = evaluate_policy(
            cfg.replace(arena=where),
            PolicyKind.RANDOM if kind == "random" else PolicyKind.GREEDY,
            STEPS,
            EVAL_SEED + seed,
            q_table=q,
            episode_steps=EPISODE,
        )
        out.append(
            (
                kind,
                seed,
                arena,
                where,
                role,
                r.progress - COLLISION_COST * r.collisions_per_1000,
                r.collisions_per_1000,
                r.progress,
            )
        )
    return out


@pytest.fixture(scope="module")
def measured() -> dict[str, list[tuple]]:
    learnt = _learnt()
    with ProcessPoolExecutor(2) as pool:
        futs = [
            pool.submit(_evaluations, k, s, a, learnt.get((k, s, a)))
            for k in KINDS
            for s in SEEDS
            for a in ARENAS
        ]
        rows = [r for f in futs for r in f.result()]
    return {k: [r for r in rows if r[0] == k] for k in KINDS}


def _folder(tmp: Path, as_real: str, measured: dict[str, list[tuple]]) -> Path:
    """A study folder whose ``standalone/qlearning`` is ``as_real`` (the untrained table may
    be both that and itself)."""
    evals = []
    for kind, run in (
        (as_real, "standalone/qlearning"),
        ("control", "control/standalone/qlearning"),
        ("untrained", "untrained"),
    ):
        evals += [
            Evaluation(run, seed, arena, arena, ITERATIONS, where, role, score, coll, prog)
            for (_k, seed, arena, where, role, score, coll, prog) in measured[kind]
        ]
    d = tmp / as_real
    d.mkdir()
    write_evaluations(d / "evaluations.csv", evals)
    return d


def _judge(d: Path) -> str:
    """``dfrl paper --from d``'s printed summary (in this process: the CLI's own function)."""
    import contextlib
    import io

    from dfrl.experiments.cli import main

    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["paper", "--from", str(d), "--resamples", "200"]) == 0
    return buf.getvalue()


def test_the_learning_control_learns_nothing(measured, tmp_path):
    out = _judge(_folder(tmp_path, "trained", measured))
    assert "check  control/standalone/qlearning: includes 0" in out, out


def test_a_clearly_learnt_run_holds(measured, tmp_path):
    out = _judge(_folder(tmp_path, "trained", measured))
    assert "L  standalone/qlearning: holds" in out, out


@pytest.mark.parametrize("as_real", ["zeros", "random", "untrained", "untrained2"])
def test_non_learners_as_real_runs_hold_no_l_contrast(measured, tmp_path, as_real):
    d = _folder(tmp_path, as_real, measured)
    out = _judge(d)
    assert "L  standalone/qlearning: holds" not in out, out
    rows = (d / "questions.csv").read_text().splitlines()
    assert not [r for r in rows if r.startswith("L,") and ",holds," in r]
