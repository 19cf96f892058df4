"""Area under a curve and evaluation-grid resolution, against values worked out by hand."""

from __future__ import annotations

import pytest

from dfrl.experiments.science.curves import auc, first_reach, grid_step, resolves


def test_auc_by_hand() -> None:
    # trapezoids on [0, 1] and [1, 3]: 1 x (0 + 2)/2 = 1 and 2 x (2 + 2)/2 = 4; span 3: 5/3
    assert auc([0, 1, 3], [0.0, 2.0, 2.0]) == pytest.approx(5.0 / 3.0)
    # a constant curve gives its constant, whatever the grid
    assert auc([100, 250, 1000], [0.4, 0.4, 0.4]) == pytest.approx(0.4)
    # a straight line gives its value at the middle of the span: (1 + 3) / 2
    assert auc([0, 1000, 4000], [1.0, 1.5, 3.0]) == pytest.approx(2.0)


def test_auc_tells_an_early_learner_from_a_late_one() -> None:
    # both end at 1; one rises over the first 1,000 of 4,000 iterations, the other over the
    # last 1,000: areas (0.5 + 3) / 4 = 0.875 and (3 x 0 + 0.5) / 4 = 0.125
    grid = [0, 1000, 2000, 3000, 4000]
    assert auc(grid, [0, 1, 1, 1, 1]) == pytest.approx(0.875)
    assert auc(grid, [0, 0, 0, 0, 1]) == pytest.approx(0.125)


def test_auc_refuses_bad_grids() -> None:
    with pytest.raises(ValueError, match="at least 2"):
        auc([0], [1.0])
    with pytest.raises(ValueError, match="increasing"):
        auc([0, 2, 1], [1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="increasing"):
        auc([0, 1, 1], [1.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="values for"):
        auc([0, 1, 2], [1.0, 1.0])
    with pytest.raises(ValueError, match="finite"):
        auc([0, 1], [1.0, float("nan")])


def test_grid_resolution() -> None:
    # the case: evaluations every 1,000 iterations cannot show a 1,000-iteration gain
    every_1000 = [0, 1000, 2000, 3000]
    assert grid_step(every_1000) == 1000.0
    assert not resolves(every_1000, 1000)
    assert resolves(every_1000, 1001)
    # the coarsest step counts: one 600 gap among 100s does not resolve 500
    uneven = [0, 100, 200, 800, 900]
    assert grid_step(uneven) == 600.0
    assert not resolves(uneven, 500) and resolves(uneven, 700)
    with pytest.raises(ValueError, match="positive"):
        resolves(every_1000, 0)


def test_first_reach_and_censoring() -> None:
    grid = [1000, 2000, 3000, 4000]
    error = [0.9, 0.8, 0.7, 0.72]
    assert first_reach(grid, error, 0.8) == 2000.0  # <= counts: reached at 2,000
    assert first_reach(grid, error, 0.75) == 3000.0  # the later rise does not undo it
    assert first_reach(grid, error, 0.6) is None  # censored: beyond 4,000
    assert first_reach(grid, [0.1, 0.5, 0.4, 0.6], 0.5, side="above") == 2000.0
    with pytest.raises(ValueError, match="side"):
        first_reach(grid, error, 0.8, side="under")
