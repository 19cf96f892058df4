"""Options of the commands that draw figures: ``--figure-format`` and ``--dpi``.

Not a command module (it registers nothing). Commands that write their figures through a
library call that draws PNGs at screen resolution (the launcher, the paper, a transfer) redraw
them with :func:`redraw_experiment` when other formats or a resolution were asked for.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from dfrl.experiments.driver.results.plots import FORMATS, parse_formats


def _formats(text: str) -> tuple[str, ...]:
    try:
        return parse_formats(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _dpi(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r}: a resolution in dots per inch, e.g. 300"
        ) from None
    if not 0 < value <= 2400:
        raise argparse.ArgumentTypeError(f"{text}: a resolution is > 0 and <= 2400 dpi")
    return value


def add_figure_arguments(p: argparse.ArgumentParser) -> None:
    """``--figure-format png,pdf,svg`` and ``--dpi N``."""
    p.add_argument(
        "--figure-format",
        type=_formats,
        default=("png",),
        metavar="FMT[,FMT]",
        help=f"formats of the figures, comma-separated, of {', '.join(FORMATS)} "
        "(pdf and svg are vector formats for print; default: png)",
    )
    p.add_argument(
        "--dpi",
        type=_dpi,
        default=None,
        help="resolution of the figures, e.g. 300 for print (default: the screen "
        "resolution of each figure, 100 or 110)",
    )


def wants_redraw(args: argparse.Namespace) -> bool:
    """Were other formats than PNG or a resolution asked for?"""
    return (
        tuple(getattr(args, "figure_format", ("png",))) != ("png",)
        or getattr(args, "dpi", None) is not None
    )


def redraw_experiment(out: Path, args: argparse.Namespace, title: str, prog: str) -> list[Path]:
    """Redraw a federated run's figures in ``out`` as asked (nothing when PNG at screen
    resolution was asked: the launcher drew those); a failure is said on stderr."""
    if not wants_redraw(args) or not (out / "metrics.csv").is_file():
        return []
    from dfrl.experiments.driver.results.plots import plot_experiment

    try:
        return plot_experiment(out, title, args.figure_format, args.dpi)
    except ImportError as exc:
        print(
            f"{prog}: figures not drawn: {exc.name or 'matplotlib'} is not installed "
            "(pip install 'dfrl[plot]')",
            file=sys.stderr,
        )
    except (OSError, ValueError) as exc:
        print(f"{prog}: figures in {out} failed: {exc}", file=sys.stderr)
    return []


def redraw_paper(out: Path, done: object, args: argparse.Namespace) -> None:
    """``dfrl paper``: the band figures and every federated run's figures, as asked."""
    if not wants_redraw(args):
        return
    import json

    from dfrl.experiments.driver.config import ConfigError, ExperimentConfig
    from dfrl.experiments.science.report.paper import figures

    try:
        figures(out, done, args.figure_format, args.dpi)
    except (OSError, ValueError) as exc:
        print(f"dfrl paper: band figures failed: {exc}", file=sys.stderr)
    for metrics in sorted(out.glob("seed*/*/metrics.csv")):
        run_dir = metrics.parent
        try:
            cfg = ExperimentConfig.from_dict(
                json.loads((run_dir / "config.json").read_text(encoding="utf-8"))
            )
            title = cfg.default_title()
        except (OSError, ValueError, ConfigError):
            title = run_dir.name
        redraw_experiment(run_dir, args, title, "dfrl paper")
