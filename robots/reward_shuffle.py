"""Shuffled rewards: the learner learns from rewards cut loose from the transitions that earned
them (the negative control "trained on shuffled rewards", issue 18).

:class:`RewardShuffle` is a seeded shuffle buffer of ``capacity`` observed rewards. Each step
the trainer hands it the reward the robot just earned and gets back the reward the learner
learns from:

* while the buffer fills (the first ``capacity`` steps) the observed reward is added and the
  learnt one is drawn uniformly from the buffer (kept in it);
* once full, the learnt reward is a uniformly drawn buffered reward, whose slot the observed
  reward takes.

So after the fill, the rewards learnt plus the ones left in :attr:`RewardShuffle.buffer` are
exactly the rewards observed (the same multiset, a seeded permutation delayed by the buffer),
and a step never learns its own reward; the reward no longer depends on the state and action
it is paired with. What the robot earns (the metrics' ``reward``) is unchanged: only the
update sees the shuffled value.
"""
from __future__ import annotations

import numpy as np


class RewardShuffle:
    """A seeded shuffle buffer of observed rewards.

    Parameters
    ----------
    capacity : int
        Rewards held (>= 1).
    rng : np.random.Generator
        The draws; the same generator state gives the same pairing.
    """

    def __init__(self, capacity: int, rng: np.random.Generator) -> None:
        if capacity < 1:
            raise ValueError(f"reward_shuffle capacity must be >= 1, got {capacity}")
        self.capacity = int(capacity)
        self._rng = rng
        self.buffer: list[float] = []

    def __call__(self, reward: float) -> float:
        """The reward to learn from in place of the observed ``reward``."""
        if len(self.buffer) < self.capacity:
            self.buffer.append(float(reward))
            return self.buffer[int(self._rng.integers(len(self.buffer)))]
        j = int(self._rng.integers(self.capacity))
        out, self.buffer[j] = self.buffer[j], float(reward)
        return out
