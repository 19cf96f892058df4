"""Did a standalone run learn? The verdict ``dfrl train`` prints at its end.

The learnt greedy policy, the greedy policy of the same learner untrained (this run's
learner before its first update) and uniform random actions each drive ``episodes`` short
evaluation episodes of ``steps`` control steps, episode ``k`` of every policy from the same
start and respawn poses (evaluation seed ``EVAL_SEED_OFFSET + 1000 * seed + k``, never a
training seed). The measure is the mean reward per step (the learner's own objective: it pays
for driving ahead and charges for near contacts and collisions; a robot spinning in place
without colliding earns only the alive bonus); collisions per 1,000 steps are reported beside
it. The verdict is the study's (:func:`dfrl.experiments.science.statistics.judge`) on the
per-episode paired difference learnt - random, from its 95% t interval:

* ``learnt: better than random by X reward per step [lo, hi]`` when the interval lies above 0;
* ``did not learn: worse than random by X [lo, hi]`` when it lies below 0 (or touches 0 from
  below);
* ``did not learn: not better than random ...`` otherwise, with the smallest difference the
  evaluation could have detected.

A learnt verdict adds when the learnt policy collides more often than random (the paired
difference of collisions per 1,000 steps above 0 at 95%): a policy that drives ahead more
earns more reward and may still hit more walls.

The same comparison against the untrained learner follows in one line. The default budget
(6 episodes x 200 steps x 3 policies: 3,600 steps, a few seconds) is said with the verdict;
a short evaluation can miss a small gain (the "not better" line says how small).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from dfrl.experiments.science.standalone import EVAL_SEED_OFFSET
from dfrl.experiments.science.statistics import (
    Interval,
    Judgement,
    Measured,
    Outcome,
    judge,
    paired,
)

__all__ = ["DEFAULT_EPISODES", "DEFAULT_STEPS", "LearningCheck", "PolicyScores", "check_learning"]

DEFAULT_EPISODES = 6
DEFAULT_STEPS = 200


@dataclass(frozen=True)
class PolicyScores:
    """One policy's evaluation: per episode, the mean reward per step and the collisions per
    1,000 steps."""

    policy: str
    rewards: tuple[float, ...]
    collisions_per_1000: tuple[float, ...]

    @property
    def mean_reward(self) -> float:
        return float(np.mean(self.rewards))

    @property
    def mean_collisions(self) -> float:
        return float(np.mean(self.collisions_per_1000))


@dataclass(frozen=True)
class LearningCheck:
    """The learnt policy against random and against the untrained learner (module doc)."""

    episodes: int
    steps: int
    seconds: float
    learnt: PolicyScores
    untrained: PolicyScores
    random: PolicyScores
    vs_random: Judgement
    vs_untrained: Judgement

    @property
    def learnt_something(self) -> bool:
        """The learnt policy beat random (the verdict holds)."""
        return self.vs_random.holds

    def verdict(self) -> str:
        """The verdict against random, in words (the module doc's)."""
        return _words(self.vs_random, "random")

    def _collision_caveat(self) -> str:
        """When the learnt policy collides more often than random (its interval above 0)."""
        more = judge(
            paired(self.learnt.collisions_per_1000, self.random.collisions_per_1000), 0.0, "above"
        )
        if not more.holds:
            return ""
        m = _interval(more)
        return (
            f"; {'but' if self.vs_random.holds else 'and'} it collides more often than "
            f"random: +{m.mean:.1f} collisions per 1,000 steps {_span(m, 1)}"
        )

    def lines(self) -> list[str]:
        """What ``dfrl train`` prints: the verdict, the untrained comparison, the three
        policies' numbers and the evaluation's budget."""
        out = [
            self.verdict() + self._collision_caveat(),
            f"against the untrained learner: "
            f"{_compared(self.vs_untrained, 'the untrained learner')}",
        ]
        for p in (self.learnt, self.untrained, self.random):
            out.append(
                f"  {p.policy:>9}: {p.mean_reward:.3f} reward per step, "
                f"{p.mean_collisions:.1f} collisions per 1,000 steps"
            )
        total = 3 * self.episodes * self.steps
        out.append(
            f"evaluation budget: 3 policies x {self.episodes} episodes x {self.steps} "
            f"steps ({total:,} steps, {self.seconds:.1f} s); 95% t intervals over the "
            f"episodes (--eval-episodes, --eval-steps)"
        )
        return out

    def to_dict(self) -> dict[str, Any]:
        """The check as JSON data (``learning_check.json``)."""

        def judged(j: Judgement) -> dict[str, Any]:
            m = _interval(j)
            return {
                "difference": m.mean,
                "low": m.low,
                "high": m.high,
                "n": m.n,
                "p": j.p,
                "outcome": j.outcome.value,
            }

        return {
            "verdict": self.verdict() + self._collision_caveat(),
            "learnt": self.learnt_something,
            "measure": "mean reward per step, paired by episode",
            "episodes": self.episodes,
            "steps": self.steps,
            "seconds": self.seconds,
            "vs_random": judged(self.vs_random),
            "vs_untrained": judged(self.vs_untrained),
            "policies": {
                p.policy: {
                    "reward_per_step": list(p.rewards),
                    "collisions_per_1000": list(p.collisions_per_1000),
                }
                for p in (self.learnt, self.untrained, self.random)
            },
            "lines": self.lines(),
        }


def _interval(j: Judgement) -> Interval:
    """The measure of one of this check's judgements: a paired t interval (:func:`paired`)."""
    assert isinstance(j.measure, Interval), j.measure
    return j.measure


def _span(m: Measured, digits: int = 3) -> str:
    return f"[{m.low:.{digits}f}, {m.high:.{digits}f}]"


def _compared(j: Judgement, other: str, unit: str = "reward per step") -> str:
    """A paired difference against ``other`` in words, without a verdict."""
    m = _interval(j)
    if j.outcome is Outcome.HOLDS:
        return f"better than {other} by {m.mean:.3f} {unit} {_span(m)}"
    if j.outcome is Outcome.REFUTED:
        how = "worse than" if m.mean < 0 else "no better than"
        return f"{how} {other} by {abs(m.mean):.3f} {unit} {_span(m)}"
    if j.outcome is Outcome.NOT_SIGNIFICANT:
        return (
            f"not better than {other} ({m.mean:+.3f} {unit} {_span(m)}; smallest "
            f"detectable difference {m.detectable():.3f})"
        )
    return f"cannot judge against {other}: {j.words()}"


def _words(j: Judgement, other: str) -> str:
    """The verdict: ``learnt: ...`` or ``did not learn: ...`` (the module doc)."""
    if j.outcome is Outcome.CANNOT_JUDGE:
        return _compared(j, other)
    return ("learnt: " if j.holds else "did not learn: ") + _compared(j, other)


def _untrained(config: Any) -> tuple[np.ndarray | None, np.ndarray | None]:
    """This run's learner before its first update: (its table, None) or (None, its
    parameters)."""
    from dfrl.robots.training import Trainer

    trainer = Trainer(config)
    try:
        if trainer.learner_kind == "tabular":
            return trainer.q_table.copy(), None
        return None, trainer.params
    finally:
        trainer.close()


def check_learning(
    config: Any,
    q_table: np.ndarray | None,
    params: np.ndarray | None,
    episodes: int = DEFAULT_EPISODES,
    steps: int = DEFAULT_STEPS,
) -> LearningCheck:
    """Evaluate a run's learnt policy against random and the untrained learner (module doc).

    Parameters
    ----------
    config : TrainerConfig
        The run's (arena, learner, seed).
    q_table : np.ndarray, shape (n_states, n_actions), or None
        A tabular learner's learnt table.
    params : np.ndarray, shape (n_params,), or None
        A function learner's learnt parameters (when ``q_table`` is None).
    episodes, steps : int
        Evaluation episodes per policy (>= 2: an interval needs two) and steps per episode.

    Raises
    ------
    ValueError
        Fewer than 2 episodes, fewer than 1 step, or neither a table nor parameters.
    """
    from dfrl.robots.evaluation import PolicyKind, evaluate_policy

    if episodes < 2:
        raise ValueError(f"--eval-episodes: at least 2 (an interval needs two), got {episodes}")
    if steps < 1:
        raise ValueError(f"--eval-steps: at least 1, got {steps}")
    if q_table is None and params is None:
        raise ValueError("no learnt table or parameters to evaluate")
    t0 = time.perf_counter()
    fresh_table, fresh_params = _untrained(config)
    policies = {
        "learnt": (PolicyKind.GREEDY, q_table, None if q_table is not None else params),
        "untrained": (PolicyKind.GREEDY, fresh_table, fresh_params),
        "random": (PolicyKind.RANDOM, None, None),
    }
    scores = {}
    for name, (kind, table, vec) in policies.items():
        results = [
            evaluate_policy(
                config,
                kind,
                steps,
                EVAL_SEED_OFFSET + 1000 * config.seed + k,
                q_table=table,
                params=vec,
            )
            for k in range(episodes)
        ]
        scores[name] = PolicyScores(
            name,
            tuple(r.mean_reward for r in results),
            tuple(r.collisions_per_1000 for r in results),
        )
    learnt, fresh, rand = scores["learnt"], scores["untrained"], scores["random"]
    return LearningCheck(
        episodes,
        steps,
        time.perf_counter() - t0,
        learnt,
        fresh,
        rand,
        judge(paired(learnt.rewards, rand.rewards), 0.0, "above"),
        judge(paired(learnt.rewards, fresh.rewards), 0.0, "above"),
    )
