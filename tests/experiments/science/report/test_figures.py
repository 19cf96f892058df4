"""Figures in PNG, PDF and SVG at a chosen resolution; curves that end with the last share."""

from __future__ import annotations

import argparse
import struct
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from dfrl.experiments.cli.figures import redraw_experiment
from dfrl.experiments.driver.results.plots import (
    draw_lines,
    new_figure,
    plot_experiment,
    save_figure,
)
from dfrl.experiments.driver.results.metrics import METRICS_FIELDS, read_metrics


def png_dpi(path: Path) -> tuple[float, float]:
    """(x, y) dots per inch from a PNG's pHYs chunk (unit 1: per metre)."""
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos = 8
    while pos < len(data):
        length, kind = struct.unpack(">I4s", data[pos : pos + 8])
        if kind == b"pHYs":
            x, y, unit = struct.unpack(">IIB", data[pos + 8 : pos + 17])
            assert unit == 1
            return x * 0.0254, y * 0.0254
        pos += 12 + length
    raise AssertionError(f"{path}: no pHYs chunk")


def tiny_results(folder: Path, older: bool = False) -> Path:
    """A ``metrics.csv`` of two robots, 50 iterations, a share at the last one that left 99.0
    (``older``: in the format before ``shared``, its own row after the last)."""
    if older:
        rows = ["robot,iteration,q_sum,cumulative_reward,collisions"]
        rows += [f"{r},{i},{0.1 * i},{0.5 * i},0" for r in ("r1", "r2") for i in range(1, 51)]
        rows += ["r1,50,99.0,25.0,0", "r2,50,99.0,25.0,0"]  # the last share's row
    else:
        rows = [",".join(METRICS_FIELDS)]
        rows += [
            f"{r},{i},{0.1 * i},{0.5 * i},0,0," if i < 50 else f"{r},50,99.0,25.0,0,1,5.0"
            for r in ("r1", "r2")
            for i in range(1, 51)
        ]
    (folder / "metrics.csv").write_text("\n".join(rows) + "\n", encoding="utf-8")
    return folder


def test_plot_experiment_writes_png_pdf_and_svg_at_the_asked_dpi(tmp_path: Path) -> None:
    paths = plot_experiment(tiny_results(tmp_path), "tiny", formats=("png", "pdf", "svg"), dpi=300)
    assert [p.name for p in paths] == [
        f"{n}.{f}" for n in ("q_sum", "cumulative_reward", "curves") for f in ("png", "pdf", "svg")
    ]
    for p in paths:
        if p.suffix == ".pdf":
            assert p.read_bytes()[:5] == b"%PDF-" and b"%%EOF" in p.read_bytes()[-64:]
        elif p.suffix == ".svg":
            assert ET.parse(p).getroot().tag == "{http://www.w3.org/2000/svg}svg"
        else:
            assert png_dpi(p) == pytest.approx((300, 300), abs=0.5)


def test_png_keeps_the_screen_resolution_by_default(tmp_path: Path) -> None:
    paths = plot_experiment(tiny_results(tmp_path), "tiny")
    assert [p.suffix for p in paths] == [".png"] * 3
    assert png_dpi(paths[0]) == pytest.approx((110, 110), abs=0.5)


def test_bad_format_or_dpi_is_refused(tmp_path: Path) -> None:
    fig = new_figure()
    with pytest.raises(ValueError, match="gif"):
        save_figure(fig, tmp_path / "f.png", ("gif",))
    with pytest.raises(ValueError, match="dpi"):
        save_figure(fig, tmp_path / "f.png", ("png",), dpi=0)


@pytest.mark.parametrize("older", [False, True])
def test_curves_end_with_the_last_share(tmp_path: Path, older: bool) -> None:
    curves = read_metrics(tiny_results(tmp_path, older) / "metrics.csv")
    ax = new_figure().subplots()
    lines = draw_lines(ax, curves, "q_sum")
    assert [(line.get_xdata()[-1], line.get_ydata()[-1]) for line in lines] == [(50, 99.0)] * 2
    assert all(len(line.get_xdata()) == 50 for line in lines)  # a point per iteration
    assert np.all(np.diff(lines[0].get_xdata()) >= 0)


def test_run_and_demo_redraw_as_asked(tmp_path: Path) -> None:
    args = argparse.Namespace(figure_format=("svg", "pdf"), dpi=200.0)
    written = redraw_experiment(tiny_results(tmp_path), args, "tiny", "dfrl run")
    assert sorted(p.name for p in written) == sorted(
        f"{n}.{f}" for n in ("q_sum", "cumulative_reward", "curves") for f in ("svg", "pdf")
    )
    # PNG at screen resolution: what the launcher drew already, nothing redrawn
    assert (
        redraw_experiment(
            tmp_path, argparse.Namespace(figure_format=("png",), dpi=None), "tiny", "dfrl run"
        )
        == []
    )


@pytest.mark.parametrize(
    "command",
    [
        ["run", "smoke2"],
        ["demo"],
        ["paper"],
        ["transfer", "--init", "t.npy", "--arena", "r1"],
        ["train"],
        ["baselines"],
        ["render-arenas"],
    ],
)
@pytest.mark.parametrize("bad", [["--figure-format", "png,gif"], ["--dpi", "0"]])
def test_figure_options_are_checked_before_anything_starts(
    command: list[str], bad: list[str]
) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "dfrl", *command, *bad], capture_output=True, text=True, timeout=60
    )
    assert done.returncode == 2
    assert ("--figure-format" if "--figure-format" in bad else "--dpi") in done.stderr
