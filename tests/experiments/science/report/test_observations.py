"""The report's tests on curves computed by hand: a learning run passes them, the negative
control (flat reward, untrained greedy policy) fails them; a test whose control passes, is
fixed by construction or shows the same effect is flagged as not a test; with too few seeds
or no control the report cannot judge."""
import numpy as np

from dfrl.experiments.science.report.observations import Test as Observation
from dfrl.experiments.science.report.measures import SeedRun, gain, rate, t_reward90
from dfrl.experiments.science.report.observations import Controls, Standing, above, paper_tests
from dfrl.experiments.science.report.verdict_text import control_words, real_words
from dfrl.experiments.science.report.verdict_text import tests_markdown as markdown_of
from dfrl.experiments.science.statistics import interval

N = 4000
DTYPE = [("iteration", "i8"), ("q_sum", "f8"), ("cumulative_reward", "f8"), ("collisions", "i8")]


def curve(rewards: np.ndarray, q_end: float) -> np.ndarray:
    c = np.zeros(len(rewards), dtype=DTYPE)
    c["iteration"] = np.arange(1, len(rewards) + 1)
    c["cumulative_reward"] = np.cumsum(rewards)
    c["q_sum"] = np.linspace(0, q_end, len(rewards)) ** 0.5 * np.sqrt(q_end)
    return c


def learning(seed: int, speed: float) -> np.ndarray:
    """Reward per step rising from 0.3 to 0.9 with time constant N / speed, plus noise."""
    t = np.arange(N)
    r = 0.9 - 0.6 * np.exp(-speed * t / N) + np.random.default_rng(seed).normal(0, 0.05, N)
    return curve(r, 300 + 10 * seed)


def flat(seed: int) -> np.ndarray:
    return curve(0.3 + np.random.default_rng(seed).normal(0, 0.05, N), 290 + 10 * seed)


def evals(score: float) -> list[dict]:
    return [{"robot": "r1", "iteration": it, "arena": a, "role": role, "score": s, "collisions_per_1000": 0.0}
            for it, s in ((N // 2, score - 0.05), (N, score))
            for a, role in (("r1", "own"), ("h1", "held_out"))]


ARENAS = {"r1": "r1", "r4": "r4", "r2": "r2"}


def run(kind: str, seed: int) -> SeedRun:
    if kind == "control":
        curves = {a: flat(seed + k) for k, a in enumerate(ARENAS)}
        ev = evals(0.02 * (seed % 3 - 1))      # an untrained policy: near 0, varying by seed
    else:
        speeds = {"r1": 12.0, "r2": 10.0, "r4": 4.0}     # R4 learns slowest
        curves = {a: learning(seed + k, speeds[a] * (1.0 if kind == "sa" else 0.6))
                  for k, a in enumerate(ARENAS)}
        ev = evals(0.7 if kind == "fed" else 0.6)
    return SeedRun(curves, dict(ARENAS), ev, {"r1": 0.0, "h1": 0.0})


def test_statistics_by_hand():
    cum = np.cumsum(np.r_[np.zeros(100), np.ones(100), np.ones(100), 2 * np.ones(100)])
    assert rate(cum, 0.0, 0.25) == 0.0 and rate(cum, 0.75, 1.0) == 2.0 and gain(cum) == 2.0
    assert t_reward90(np.arange(1, 401), np.cumsum(np.full(400, 0.3))) == 400   # no gain


def _tests(seeds: range, control: bool = True) -> dict[str, Observation]:
    fed = {"qlearning/average": [run("fed", s) for s in seeds]}
    sa = {"qlearning": [run("sa", s) for s in seeds]}
    ctrl_f = [run("control", s) for s in seeds] if control else []
    ctrl_s = [run("control", s + 10) for s in seeds] if control else []
    controls = Controls(shuffled_fed=ctrl_f, shuffled_sa=ctrl_s)
    return {t.key: t for t in paper_tests(fed, sa, controls)}


def test_control_fails_the_tests_that_real_runs_pass():
    tests = _tests(range(1, 6))
    # the Q-sum rises in every run, control included: not a test of learning
    assert tests["1a"].holds and tests["1a"].control_passes and not tests["1a"].is_test
    assert tests["1a"].standing()[1].startswith("the control passes it too")
    for key in ("1b", "1c", "6"):
        assert tests[key].holds, (key, tests[key].real)
        assert not tests[key].control_passes, (key, tests[key].control)
        assert tests[key].standing()[0] is Standing.TEST, (key, tests[key].standing())
    assert interval([1.0, 1.0]).half == 0.0


def test_controls_fixed_by_construction_are_not_tests():
    tests = _tests(range(1, 6))
    # 4 and 5: the control's reward never gains 0.05, so t_reward90 is the budget in every
    # control run and R4 minus R1, federated minus standalone, are 0 in every seed: found from
    # the data (the real runs hold both)
    for key in ("4", "5"):
        standing, why = tests[key].standing()
        assert tests[key].holds and standing is Standing.NOT_A_TEST
        assert "is 0 in every seed" in why and "t_reward90 is the budget" in why
    assert control_words(tests["5"]) == "fixed by construction"
    md = "\n".join(markdown_of(list(tests.values())))
    assert "**not a test**: the control's result is fixed by construction" in md
    assert "Holm's correction over the family of all" in md


def test_a_control_with_the_same_effect_makes_it_not_a_test():
    # Prepare: real differences 0.1 in every seed (holds); the control's differences 0.3,
    # -0.1, 0.2, -0.05, 0.2 (mean 0.11, interval includes 0: it fails the claim), but real
    # minus control, paired by seed: -0.2, 0.2, -0.1, 0.15, -0.1 (mean -0.01, includes 0)
    real = [above("federated", [0.1] * 5)]
    ctrl = [above("control", [0.3, -0.1, 0.2, -0.05, 0.2])]
    # Execute
    t = Observation("6", "held-out", "how", real, ctrl)
    # Assert
    assert t.holds and not t.control_passes
    standing, why = t.standing()
    assert standing is Standing.NOT_A_TEST
    assert why.startswith("the control shows the same effect: federated minus control is ")
    assert "not significant at n = 5" in why


def test_too_few_seeds_or_no_control_cannot_judge():
    two = _tests(range(1, 3))
    for key in ("1a", "1b", "1c", "4", "6"):
        standing, why = two[key].standing()
        assert standing is Standing.CANNOT_JUDGE and "fewer than 3" in why, (key, why)
        assert not two[key].is_test
    assert str(two["1b"].real[0].judgement) == "cannot judge (n = 2 < 3)"
    assert real_words(two["1b"]).startswith("holds for 0 of")
    assert control_words(two["1b"]) == "fewer than 3 seeds"
    none = _tests(range(1, 6), control=False)
    assert "1e" not in none
    for t in none.values():
        assert t.standing() == (Standing.CANNOT_JUDGE, "no control run applies")
        assert control_words(t) == "none"
