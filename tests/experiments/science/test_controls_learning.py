"""Controls that can fail, on real training (pybullet, tiny budgets): a trained table passes a
test of learning that the zero table fails; the shuffled-reward control, which cannot have
learned from the reward, drives ahead in some seeds at this budget, and the report's machinery
then refuses to call the test one of learning; one seed or no control: cannot judge.

Budget and seeds chosen by measurement (R1, Q-learning, 3,000 iterations, seeds 1-3; greedy
score in R1 and h1, 400 steps each in episodes of 100, evaluation seed 50,000 + seed, as the
report evaluates): trained 0.63/0.77, 0.56/0.22, 0.64/0.55; zero table 0.07/-0.06,
0.11/-0.27, 0.24/0.11; shuffled rewards (buffer 1,000) 0.86/0.77, 0.71/0.26, 0.00/0.00.
The shuffled rewards are the ``raw`` mode, the control before issue 34, kept here as an
example of a control that passes (the default mode no longer does: robots/README.md,
"Controls").
"""
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import pytest

from dfrl.experiments.science.report.standing import Standing, above
from dfrl.experiments.science.report.standing import Test as Observation
from dfrl.experiments.science.report.verdict_text import summary_markdown
from dfrl.experiments.science.studies.history import eval_job
from dfrl.robots.training import TrainerConfig, train

SEEDS = (1, 2, 3)
ITERATIONS = 3000
ARENAS = ("r1", "h1")
STEPS, EPISODE = 400, 100


def _scores(seed: int, shuffle: int | None) -> float:
    """Mean greedy score over ARENAS of a table trained in R1 (None: the zero table)."""
    cfg = TrainerConfig(arena="r1", seed=seed, iterations=ITERATIONS,
                        reward_shuffle=shuffle or 0, reward_shuffle_mode="raw")
    q = np.zeros((81, 3)) if shuffle is None else train(cfg).q_table
    return float(np.mean([eval_job(cfg.to_dict(), q, a, STEPS, EPISODE, 50_000 + seed)["score"]
                          for a in ARENAS]))


@pytest.fixture(scope="module")
def scores() -> dict[str, list[float]]:
    kinds = {"trained": 0, "shuffled": 1000, "zero": None}
    with ProcessPoolExecutor(2) as pool:
        futs = {k: [pool.submit(_scores, s, v) for s in SEEDS] for k, v in kinds.items()}
        return {k: [f.result() for f in fs] for k, fs in futs.items()}


def _test(real, controls) -> Observation:
    return Observation("t", "The learnt greedy policy drives", "mean greedy score over R1 and h1",
                [above("trained", real, 0.1)], [above(k, v, 0.1) for k, v in controls])


def test_the_zero_table_fails_where_the_trained_table_passes(scores):
    t = _test(scores["trained"], [("zero table", scores["zero"])])
    assert t.holds, t.real
    assert not t.control_passes, t.control
    assert t.standing() == (Standing.TEST, "every control fails it and differs from every run "
                                           "that passes")
    assert any(line.endswith("| yes |") for line in summary_markdown([t]))


def test_the_shuffled_reward_control_shows_the_effect_here_so_it_is_not_a_test(scores):
    # the shuffled-reward tables drive ahead in seeds 1 and 2: a control that can pass
    assert max(scores["shuffled"]) > min(scores["trained"])
    t = _test(scores["trained"], [("zero table", scores["zero"]),
                                  ("shuffled rewards", scores["shuffled"])])
    standing, why = t.standing()
    assert standing is Standing.NOT_A_TEST
    assert why.startswith("the control shows the same effect: trained minus shuffled rewards")
    assert not any("| yes" in line for line in summary_markdown([t]))


def test_one_seed_or_no_control_cannot_judge(scores):
    one = _test(scores["trained"][:1], [("zero table", scores["zero"][:1])])
    none = _test(scores["trained"], [])
    assert one.standing() == (Standing.CANNOT_JUDGE, "1 seed(s) in a row, fewer than 3")
    assert none.standing() == (Standing.CANNOT_JUDGE, "no control run applies")
    lines = summary_markdown([one, none])
    assert not any("| yes" in line for line in lines)
    assert sum("cannot judge" in line for line in lines) == 2
