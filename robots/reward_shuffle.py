"""The learning control: the learner learns from outcomes cut loose from the transitions that
earned them, so it cannot learn what a test of learning asks (issues 18 and 34).

:class:`RewardShuffle` is a seeded shuffle buffer of ``capacity`` observed outcomes, an outcome
being a step's reward and whether the step ended the episode for the update (a collision).
Each step the trainer hands it the outcome the robot just had and gets back the one the learner
learns from. The draw is the same in every :class:`ShuffleMode`:

* while the buffer fills (the first ``capacity`` steps) the observed outcome is added and the
  drawn one is drawn uniformly from the buffer (kept in it);
* once full, the drawn outcome is a uniformly drawn buffered one, whose slot the observed
  outcome takes.

So after the fill, the outcomes drawn plus the ones left in :attr:`RewardShuffle.buffer` are
exactly the outcomes observed (the same multiset, a seeded permutation delayed by the buffer),
and a step never draws its own: neither the reward nor the end of the episode depends on the
state and action they are paired with. What the learner then learns depends on the mode:

``centred_no_bootstrap`` (the default, issue 34)
    The drawn reward minus the mean reward of the buffer it was drawn from, and every update
    terminal. The learnt reward has mean 0 given the buffer, whatever the state, action and
    visit count, and nothing is bootstrapped from the real next state, so a Q-value is a
    visit-weighted average of noise with mean 0: it cannot grow with visits nor carry the
    arena's dynamics. The greedy action of a state is the argmax of noise, as in a table of
    random numbers.
``centred``
    The drawn reward minus the buffer's mean, with the drawn end flag: the learner still
    bootstraps on the real next state (its values stay near 0, but the bootstrap carries which
    states follow which, and max-bootstrap bias grows with the visits of the next state).
``raw``
    The drawn outcome as it is (the control before issue 34). With mostly positive rewards the
    values grow with visits, so the most-visited action becomes greedy, and actions leading to
    often-visited open states bootstrap higher: such tables drove ahead (measured:
    robots/README.md "Controls"). Kept so that configurations written before issue 34 can be
    re-run as they ran.

The measured greedy scores of all of these against the zero table are in robots/README.md,
"Controls". What the robot earns and where it respawns are unchanged: only the update sees
the control's outcome.
"""

from __future__ import annotations

from enum import Enum

import numpy as np


class ShuffleMode(str, Enum):
    """What the learner learns from the drawn outcome (see the module doc)."""

    CENTRED_NO_BOOTSTRAP = "centred_no_bootstrap"
    CENTRED = "centred"
    RAW = "raw"


#: The mode of a configuration that sets ``reward_shuffle`` and no ``reward_shuffle_mode``.
DEFAULT_MODE: ShuffleMode = ShuffleMode.CENTRED_NO_BOOTSTRAP


class RewardShuffle:
    """A seeded shuffle buffer of observed outcomes (reward, terminal).

    Parameters
    ----------
    capacity : int
        Outcomes held (>= 1).
    rng : np.random.Generator
        The draws; the same generator state gives the same pairing.
    mode : ShuffleMode or its value
        What is learnt from the drawn outcome (default :data:`DEFAULT_MODE`).

    Attributes
    ----------
    buffer : list of (float, bool)
        The outcomes held, in slot order.
    drawn : tuple of (float, bool) or None
        The outcome drawn at the last call, before centring (None before the first).

    Raises
    ------
    ValueError
        ``capacity`` < 1 or an unknown mode.
    """

    def __init__(
        self, capacity: int, rng: np.random.Generator, mode: ShuffleMode | str = DEFAULT_MODE
    ) -> None:
        if capacity < 1:
            raise ValueError(f"reward_shuffle capacity must be >= 1, got {capacity}")
        self.capacity = int(capacity)
        self.mode = shuffle_mode(mode)
        self._rng = rng
        self.buffer: list[tuple[float, bool]] = []
        self.drawn: tuple[float, bool] | None = None
        self._sum = 0.0  # of the buffered rewards, recomputed exactly every capacity calls
        self._calls = 0

    def mean(self) -> float:
        """Mean reward of the buffered outcomes (0 while empty)."""
        return self._sum / len(self.buffer) if self.buffer else 0.0

    def __call__(self, reward: float, terminal: bool) -> tuple[float, bool]:
        """The (reward, terminal) to learn from in place of the observed ones."""
        seen = (float(reward), bool(terminal))
        self._calls += 1
        if self._calls % self.capacity == 0:  # no drift of the running sum
            self._sum = float(np.sum([r for r, _ in self.buffer]))
        if len(self.buffer) < self.capacity:
            self.buffer.append(seen)
            self._sum += seen[0]
            out = self.buffer[int(self._rng.integers(len(self.buffer)))]
            mean = self.mean()
        else:
            j = int(self._rng.integers(self.capacity))
            out, mean = self.buffer[j], self.mean()
            self.buffer[j] = seen
            self._sum += seen[0] - out[0]
        self.drawn = out
        if self.mode is ShuffleMode.RAW:
            return out
        if self.mode is ShuffleMode.CENTRED:
            return out[0] - mean, out[1]
        return out[0] - mean, True


def shuffle_mode(mode: ShuffleMode | str) -> ShuffleMode:
    """``mode`` as a :class:`ShuffleMode`.

    Raises
    ------
    ValueError
        Not a mode's value (the message lists them).
    """
    try:
        return ShuffleMode(mode)
    except ValueError:
        raise ValueError(
            f"reward_shuffle_mode must be one of {[m.value for m in ShuffleMode]}, got {mode!r}"
        ) from None
