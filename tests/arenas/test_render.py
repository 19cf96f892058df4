"""Arena renders: the floor ends at the walls; the plotted view has a heading marker and,
asked for, the sensor rays."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dfrl.arenas.spec import load_arena
from dfrl.experiments.cli import main


def floor_mask(img: np.ndarray) -> np.ndarray:
    """Pixels of the floor's colour (warm light grey, lit): R = G > B, all above 200."""
    r, g, b = (img[..., k].astype(int) for k in range(3))
    return (r > 200) & (abs(r - g) <= 2) & (r - b >= 4) & (r < 250)


@pytest.mark.parametrize("name", ["r1", "r4"])
def test_the_floor_is_drawn_within_the_walls_only(name: str) -> None:
    from dfrl.robots.world import World

    spec = load_arena(name)
    world = World(spec)
    try:
        world.place_robot(10.0 * max(spec.size), 0.0, 0.0)  # out of the picture
        size = 220
        img = world.render_top(size, size)
    finally:
        world.close()
    extent = max(spec.size) + 0.1  # render_top's field of view
    rows, cols = np.nonzero(floor_mask(img))
    assert len(rows) > 0.3 * size * size  # the floor is there
    x = (cols + 0.5) / size * extent - extent / 2
    y = extent / 2 - (rows + 0.5) / size * extent
    px = extent / size
    assert np.all(np.abs(x) <= spec.size[0] / 2 + px)  # ... and ends at the walls
    assert np.all(np.abs(y) <= spec.size[1] / 2 + px)
    assert not floor_mask(img[:1, :1]).any()  # the margin is background


def test_render_arenas_draws_heading_and_sensor_rays(tmp_path: Path) -> None:
    plain, rays = tmp_path / "plain", tmp_path / "rays"
    assert main(["render-arenas", "--arena", "r1", "--out", str(plain), "--size", "120"]) == 0
    assert (
        main(["render-arenas", "--arena", "r1", "--out", str(rays), "--size", "120", "--rays"]) == 0
    )
    a = plt_image(plain / "arena_r1.png")
    b = plt_image(rays / "arena_r1.png")
    assert a.shape == b.shape
    red = (b[..., 0] > 0.6) & (b[..., 1] < 0.45) & (b[..., 2] < 0.45)  # tab:red rays
    red_before = (a[..., 0] > 0.6) & (a[..., 1] < 0.45) & (a[..., 2] < 0.45)
    assert red.sum() > red_before.sum() + 50


def plt_image(path: Path) -> np.ndarray:
    from matplotlib.image import imread

    return imread(path)


def test_the_heading_marker_points_along_the_start_yaw() -> None:
    import math

    from dfrl.experiments.driver.results.plots import new_figure
    from dfrl.robots.plots import draw_arena

    spec = load_arena("r1")
    x, y, yaw = spec.start.pose
    ax = new_figure().subplots()
    art = draw_arena(ax, np.zeros((8, 8, 3), np.uint8), spec, rays=np.zeros((8, 2, 2)))
    (tx, ty), (hx, hy) = art["heading"].xy, art["heading"].xyann
    assert (hx, hy) == (x, y)
    assert math.atan2(ty - y, tx - x) == pytest.approx(yaw)
    assert len(art["rays"]) == 8
