"""The learning control in the batched simulator: :class:`dfrl.robots.reward_shuffle.RewardShuffle`
for many robots, compiled, with the same draws from the same (third) stream of each seed.

Per robot ``i``: ``buffer[i, j] = (reward, terminal)`` of slot ``j``; ``meta[i]`` holds the
capacity (0: the control is off), the mode code of :data:`MODES`, the slots filled and the calls
so far; ``total[i]`` the running sum of the buffered rewards.
"""

from __future__ import annotations

from numba import njit

from dfrl.robots.reward_shuffle import ShuffleMode

#: Mode codes in ``meta[:, M_MODE]``.
MODES: dict[ShuffleMode, int] = {
    ShuffleMode.CENTRED_NO_BOOTSTRAP: 0,
    ShuffleMode.CENTRED: 1,
    ShuffleMode.RAW: 2,
}
M_CAPACITY, M_MODE, M_FILLED, M_CALLS = 0, 1, 2, 3


@njit(cache=True)
def learnt_outcome(i, reward, terminal, buffer, meta, total, rng):
    """The (reward, terminal) robot ``i``'s update learns from (``RewardShuffle.__call__``)."""
    cap = meta[i, M_CAPACITY]
    meta[i, M_CALLS] += 1
    filled = meta[i, M_FILLED]
    if meta[i, M_CALLS] % cap == 0:  # no drift of the running sum
        s = 0.0
        for j in range(filled):
            s += buffer[i, j, 0]
        total[i] = s
    if filled < cap:
        buffer[i, filled, 0] = reward
        buffer[i, filled, 1] = 1.0 if terminal else 0.0
        filled += 1
        meta[i, M_FILLED] = filled
        total[i] += reward
        j = rng.integers(0, filled)
        out_r, out_t = buffer[i, j, 0], buffer[i, j, 1] > 0.0
        mean = total[i] / filled
    else:
        j = rng.integers(0, cap)
        out_r, out_t = buffer[i, j, 0], buffer[i, j, 1] > 0.0
        mean = total[i] / filled
        buffer[i, j, 0] = reward
        buffer[i, j, 1] = 1.0 if terminal else 0.0
        total[i] += reward - out_r
    mode = meta[i, M_MODE]
    if mode == 2:
        return out_r, out_t
    if mode == 1:
        return out_r - mean, out_t
    return out_r - mean, True
