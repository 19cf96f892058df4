"""The linear learner's feature map: a bias plus 1-D tile codings of each sensor.

Each of the ``obs_dim`` proximities ``p_i`` in ``[0, 1]`` is coded on its own by ``tilings``
overlapping tilings of ``tiles`` tiles each. Tiling ``k`` (0-based) is offset by ``k/tilings``
of a tile width ``1/(tiles - 1)``, so ``p_i`` falls into its tile

    j = floor(p_i * (tiles - 1) + k / tilings)          (0 <= j <= tiles - 1)

(``p_i = 0``, nothing in range, is tile 0 of every tiling). The feature vector is binary with
``1 + obs_dim * tilings`` ones among

    n_features = 1 + obs_dim * tilings * tiles

entries: index 0 is the bias (always 1), and sensor ``i``, tiling ``k``, tile ``j`` is index
``1 + (i * tilings + k) * tiles + j``. A linear model over these features is a sum of one
piecewise-constant function per sensor (resolution ``1 / ((tiles - 1) * tilings)``) and a
constant; it generalises between nearby readings of one sensor, not across sensors.

Defaults: 4 tilings of 8 tiles (resolution 1/28 of the 6 cm range, about 2 mm), 257 features,
33 active.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TileCoding:
    """Shape of the per-sensor tile coding.

    Attributes
    ----------
    tilings : int
        Offset tilings per sensor (>= 1).
    tiles : int
        Tiles per tiling (>= 2).
    """

    tilings: int = 4
    tiles: int = 8

    def __post_init__(self) -> None:
        if self.tilings < 1:
            raise ValueError(f"tilings must be >= 1, got {self.tilings}")
        if self.tiles < 2:
            raise ValueError(f"tiles must be >= 2, got {self.tiles}")

    def n_features(self, obs_dim: int) -> int:
        """Length of the feature vector for ``obs_dim`` sensors."""
        return 1 + obs_dim * self.tilings * self.tiles

    def n_active(self, obs_dim: int) -> int:
        """Ones in every feature vector (the bias and one tile per sensor and tiling)."""
        return 1 + obs_dim * self.tilings


def active_features(obs: np.ndarray, coding: TileCoding) -> np.ndarray:
    """Indices of the ones of the feature vector of ``obs`` (see the module doc).

    Parameters
    ----------
    obs : np.ndarray, shape (obs_dim,)
        Proximities; values outside ``[0, 1]`` are clipped.
    coding : TileCoding

    Returns
    -------
    np.ndarray, int64, shape (1 + obs_dim * tilings,)
        The bias index 0, then sensor by sensor, tiling by tiling.
    """
    p = np.clip(np.asarray(obs, dtype=np.float64), 0.0, 1.0)
    t, n = coding.tilings, coding.tiles
    offsets = np.arange(t, dtype=np.float64) / t  # (tilings,)
    tile = np.floor(p[:, None] * (n - 1) + offsets[None, :]).astype(np.int64)
    tile = np.minimum(tile, n - 1)  # guards rounding only
    base = 1 + (np.arange(p.shape[0])[:, None] * t + np.arange(t)[None, :]) * n
    return np.concatenate([np.zeros(1, dtype=np.int64), (base + tile).ravel()])


def feature_vector(obs: np.ndarray, coding: TileCoding) -> np.ndarray:
    """The dense binary feature vector of ``obs``, float64, shape (n_features,)."""
    phi = np.zeros(coding.n_features(np.asarray(obs).shape[0]), dtype=np.float64)
    phi[active_features(obs, coding)] = 1.0
    return phi


def feature_matrix(obs: np.ndarray, coding: TileCoding) -> np.ndarray:
    """Dense binary feature vectors of a batch, float64, shape (B, n_features).

    Parameters
    ----------
    obs : np.ndarray, shape (B, obs_dim)
    coding : TileCoding
    """
    x = np.asarray(obs, dtype=np.float64)
    x = x.reshape(1, -1) if x.ndim == 1 else x
    phi = np.zeros((x.shape[0], coding.n_features(x.shape[1])), dtype=np.float64)
    for i, row in enumerate(x):
        phi[i, active_features(row, coding)] = 1.0
    return phi
