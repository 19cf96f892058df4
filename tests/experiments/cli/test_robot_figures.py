"""``--figure-format`` and ``--dpi`` on the standalone robot commands (train, baselines,
render-arenas): every asked format is written, PDF and SVG are well formed, a PNG carries the
asked resolution, and the screen resolution stays the default."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from dfrl.experiments.cli import main

from ..science.report.test_figures import png_dpi


def _check(first: Path, formats: tuple[str, ...], dpi: float) -> None:
    for fmt in formats:
        path = first.with_suffix(f".{fmt}")
        data = path.read_bytes()
        if fmt == "pdf":
            assert data[:5] == b"%PDF-" and b"%%EOF" in data[-64:], path
        elif fmt == "svg":
            assert ET.parse(path).getroot().tag == "{http://www.w3.org/2000/svg}svg", path
        else:
            assert png_dpi(path) == pytest.approx((dpi, dpi), abs=0.5), path


def test_render_arenas_in_three_formats_at_300_dpi(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert (
        main(
            [
                "render-arenas",
                "--arena",
                "r1",
                "r3",
                "--out",
                str(tmp_path),
                "--size",
                "120",
                "--figure-format",
                "png,pdf,svg",
                "--dpi",
                "300",
            ]
        )
        == 0
    )
    for name in ("arena_r1", "arena_r3", "arenas"):
        _check(tmp_path / f"{name}.png", ("png", "pdf", "svg"), 300)
    printed = capsys.readouterr().out.split()
    assert len(printed) == 9 and str(tmp_path / "arenas.svg") in printed


def test_train_and_baselines_write_the_asked_formats(tmp_path: Path) -> None:
    run = tmp_path / "run"
    assert (
        main(
            [
                "train",
                "--arena",
                "r1",
                "--iterations",
                "150",
                "--seed",
                "1",
                "--out",
                str(run),
                "--no-progress",
                "--figure-format",
                "pdf,svg",
            ]
        )
        == 0
    )
    _check(run / "learning_curves.pdf", ("pdf", "svg"), 0)
    assert not (run / "learning_curves.png").exists()
    base = tmp_path / "base"
    assert (
        main(
            [
                "baselines",
                "--out",
                str(base),
                "--iterations",
                "150",
                "--arenas",
                "r1",
                "--algos",
                "sarsa",
                "--jobs",
                "1",
                "--dpi",
                "200",
            ]
        )
        == 0
    )
    _check(base / "baseline_sarsa.png", ("png",), 200)


def test_the_default_is_png_at_screen_resolution(tmp_path: Path) -> None:
    assert main(["render-arenas", "--arena", "r2", "--out", str(tmp_path), "--size", "100"]) == 0
    _check(tmp_path / "arena_r2.png", ("png",), 100)
    assert not (tmp_path / "arena_r2.pdf").exists()
