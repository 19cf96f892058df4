"""The report's tests on curves computed by hand: a learning run passes them, the negative
control (flat reward, untrained greedy policy) fails them; a test the control passes is
flagged as not a test."""
import numpy as np

from dfrl.experiments.science.report.observations import (SeedRun, gain, paper_tests, rate, t_reward90)
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
        ev = evals(0.0)
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


def test_control_fails_the_tests_that_real_runs_pass():
    seeds = range(1, 6)
    fed = {"qlearning/average": [run("fed", s) for s in seeds]}
    sa = {"qlearning": [run("sa", s) for s in seeds]}
    tests = {t.key: t for t in paper_tests(fed, sa, [run("control", s) for s in seeds],
                                           [run("control", s + 10) for s in seeds])}
    # the Q-sum rises in every run, control included: not a test of learning
    assert tests["1a"].holds and tests["1a"].control_passes and not tests["1a"].is_test
    # 1e has the control as its reference: the control row fails by construction
    assert tests["1e"].holds and not tests["1e"].control_passes
    for key in ("1b", "1c", "4", "6"):
        assert tests[key].holds, (key, tests[key].real)
        assert not tests[key].control_passes, (key, tests[key].control)
        assert tests[key].is_test
    # synthetic federated robots learn slower than standalone ones: test 5 holds, control fails
    assert tests["5"].holds and not tests["5"].control_passes
    assert interval([1.0, 1.0]).half == 0.0
