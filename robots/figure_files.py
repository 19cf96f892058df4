"""Writing a figure to files: the formats (PNG, or PDF and SVG for print) and the resolution
asked for. Shared by every figure of dfrl (the robots' learning curves and arenas, and the
experiments' figures in :mod:`dfrl.experiments.driver.results.plots`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["FORMATS", "SCREEN_DPI", "parse_formats", "save_figure"]

#: Formats a figure can be written in (matplotlib's names, which are the file suffixes).
FORMATS = ("png", "pdf", "svg")

#: Resolution of a PNG when none is asked for (screen).
SCREEN_DPI = 110


def parse_formats(text: str) -> tuple[str, ...]:
    """``"png,pdf"`` -> ``("png", "pdf")`` (order kept, repeats dropped).

    Raises
    ------
    ValueError
        Empty, or a format not in :data:`FORMATS`.
    """
    names = tuple(dict.fromkeys(f.strip().lower() for f in text.split(",") if f.strip()))
    bad = [f for f in names if f not in FORMATS]
    if not names or bad:
        raise ValueError(
            f"figure format {', '.join(bad) or repr(text)}: "
            f"use a comma-separated list of {', '.join(FORMATS)}"
        )
    return names


def save_figure(
    fig: Any,
    path: str | Path,
    formats: Sequence[str] = ("png",),
    dpi: float | None = None,
    default_dpi: float = SCREEN_DPI,
) -> list[Path]:
    """Write ``fig`` as ``path`` with each suffix of ``formats`` (``q_sum.png``,
    ``q_sum.pdf``, ...) at ``dpi`` (``default_dpi`` when None); return the files written.

    Raises
    ------
    ValueError
        A format not in :data:`FORMATS`, or a dpi that is not positive.
    """
    bad = [f for f in formats if f not in FORMATS]
    if bad or not formats:
        raise ValueError(f"figure formats {list(formats)}: use some of {', '.join(FORMATS)}")
    if dpi is not None and not dpi > 0:
        raise ValueError(f"figure dpi {dpi}: must be > 0")
    base = Path(path)
    base.parent.mkdir(parents=True, exist_ok=True)
    out = []
    for fmt in formats:
        target = base.with_suffix(f".{fmt}")
        fig.savefig(target, format=fmt, dpi=dpi or default_dpi)
        out.append(target)
    return out
