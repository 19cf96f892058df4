"""Learning curves as numbers: smoothing, the time to a fraction of the gain, late growth,
reward rates, dips, and measures over an evaluation grid (area under the curve, the grid's
step, whether it resolves an effect, the first point that reaches a level). Pure functions of
arrays; the intervals and verdicts over seeds are in :mod:`.statistics`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def smooth(y: np.ndarray, window: int = 200) -> np.ndarray:
    """Moving average (same length; the window shrinks at the start)."""
    y = np.asarray(y, dtype=np.float64)
    if len(y) == 0 or window <= 1:
        return y
    c = np.cumsum(np.insert(y, 0, 0.0))
    idx = np.arange(1, len(y) + 1)
    lo = np.maximum(0, idx - window)
    return (c[idx] - c[lo]) / (idx - lo)


def t_fraction(it: np.ndarray, y: np.ndarray, frac: float = 0.9) -> int:
    """First iteration at which the (smoothed) curve reaches ``frac`` of its final value."""
    ys = smooth(y)
    final = ys[-1]
    if final <= 0:
        return int(it[-1])
    hit = np.nonzero(ys >= frac * final)[0]
    return int(it[hit[0]]) if len(hit) else int(it[-1])


def late_growth(y: np.ndarray) -> float:
    """Growth over the last quarter as a fraction of the total growth (small: saturated)."""
    ys = smooth(y)
    n = len(ys)
    total = ys[-1] - ys[0]
    if n < 4 or total == 0:
        return float("nan")
    return float((ys[-1] - ys[int(0.75 * n)]) / total)


def reward_rate(y: np.ndarray, part: str) -> float:
    """Mean reward per iteration over the first or last quarter of a cumulative curve."""
    n = len(y)
    q = max(1, n // 4)
    if part == "first":
        return float(y[q - 1] / q)
    return float((y[-1] - y[n - q - 1]) / q)


def dip(y: np.ndarray) -> tuple[float, int]:
    """Largest drop of the smoothed curve below its running peak, as a fraction of that peak,
    and the iteration index where it bottoms."""
    ys = smooth(y, 100)
    peak = np.maximum.accumulate(ys)
    with np.errstate(divide="ignore", invalid="ignore"):
        drop = np.where(peak > 0, (peak - ys) / peak, 0.0)
    k = int(np.argmax(drop))
    return float(drop[k]), k


def _grid(
    iterations: Sequence[float], values: Sequence[float] | None = None
) -> tuple[np.ndarray, np.ndarray | None]:
    """An evaluation grid checked: at least 2 finite, strictly increasing points, and as many
    finite values."""
    x = np.asarray(iterations, dtype=np.float64)
    if x.ndim != 1 or len(x) < 2:
        raise ValueError(f"a grid needs at least 2 points, got {x.shape}")
    if not np.isfinite(x).all() or (np.diff(x) <= 0).any():
        raise ValueError("grid points must be finite and strictly increasing")
    if values is None:
        return x, None
    y = np.asarray(values, dtype=np.float64)
    if y.shape != x.shape:
        raise ValueError(f"{len(y)} values for {len(x)} grid points")
    if not np.isfinite(y).all():
        raise ValueError("values must be finite")
    return x, y


def auc(iterations: Sequence[float], values: Sequence[float]) -> float:
    """Area under a curve measured on an evaluation grid, normalised by the span: the
    trapezoid rule's integral divided by ``iterations[-1] - iterations[0]``, i.e. the curve's
    mean level over the span, in the values' unit (a constant curve gives its constant).

    Raises
    ------
    ValueError
        Fewer than 2 points, a grid not strictly increasing, lengths differ, or a value not
        finite.
    """
    x, y = _grid(iterations, values)
    assert y is not None
    area = float(np.sum(np.diff(x) * (y[1:] + y[:-1]) / 2.0))
    return area / float(x[-1] - x[0])


def grid_step(iterations: Sequence[float]) -> float:
    """The largest step of an evaluation grid: the coarsest time it resolves."""
    x, _ = _grid(iterations)
    return float(np.max(np.diff(x)))


def resolves(iterations: Sequence[float], effect: float) -> bool:
    """Whether the grid is finer than an effect: every step strictly smaller than ``effect``,
    a difference in time (iterations) that a measure on this grid is meant to show. A grid
    whose step equals the effect cannot tell a difference of one step from none.

    Raises
    ------
    ValueError
        A bad grid, or ``effect <= 0``.
    """
    if not effect > 0:
        raise ValueError(f"the effect must be a positive time, got {effect}")
    return grid_step(iterations) < effect


def first_reach(
    iterations: Sequence[float], values: Sequence[float], level: float, side: str = "below"
) -> float | None:
    """The first grid point at which a curve reaches ``level`` (``side="below"``: a value
    ``<= level``, as an error falls; ``"above"``: ``>= level``, as a score rises), or None
    when it never does within the grid: a censored time, known only to exceed the last point.
    No interpolation: the time is known to the grid step (:func:`grid_step`).

    Raises
    ------
    ValueError
        A bad grid or values (as :func:`auc`), or ``side`` not ``below``/``above``.
    """
    x, y = _grid(iterations, values)
    assert y is not None
    if side not in ("below", "above"):
        raise ValueError(f"side must be 'below' or 'above', got {side!r}")
    hit = np.nonzero(y <= level if side == "below" else y >= level)[0]
    return float(x[hit[0]]) if len(hit) else None
