"""Shuffled rewards: the learner learns from rewards cut loose from the transitions that earned
them (the negative control "trained on shuffled rewards", issue 18).

:class:`RewardShuffle` is a seeded shuffle buffer of ``capacity`` observed outcomes, an outcome
being a step's reward and whether the step ended the episode for the update (a collision).
Each step the trainer hands it the outcome the robot just had and gets back the one the learner
learns from:

* while the buffer fills (the first ``capacity`` steps) the observed outcome is added and the
  learnt one is drawn uniformly from the buffer (kept in it);
* once full, the learnt outcome is a uniformly drawn buffered one, whose slot the observed
  outcome takes.

So after the fill, the outcomes learnt plus the ones left in :attr:`RewardShuffle.buffer` are
exactly the outcomes observed (the same multiset, a seeded permutation delayed by the buffer),
and a step never learns its own; neither the reward nor the end of the episode depends on
the state and action they are paired with. The end-of-episode flag travels with its reward:
shuffling the reward alone leaves a signal, since a pair that ends in a collision is not
bootstrapped and its value stays below the others' (measured: tables trained on shuffled
rewards alone drove ahead without colliding in 2 of 6 seeds, robots/README.md "Controls").
What the robot earns and where it respawns are unchanged: only the update sees the shuffled
outcome.
"""
from __future__ import annotations

import numpy as np


class RewardShuffle:
    """A seeded shuffle buffer of observed outcomes (reward, terminal).

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
        self.buffer: list[tuple[float, bool]] = []

    def __call__(self, reward: float, terminal: bool) -> tuple[float, bool]:
        """The (reward, terminal) to learn from in place of the observed ones."""
        seen = (float(reward), bool(terminal))
        if len(self.buffer) < self.capacity:
            self.buffer.append(seen)
            return self.buffer[int(self._rng.integers(len(self.buffer)))]
        j = int(self._rng.integers(self.capacity))
        out, self.buffer[j] = self.buffer[j], seen
        return out
