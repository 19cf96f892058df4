"""``--tensorboard`` of ``dfrl run``, ``demo``, ``collect`` and ``train``: the option
(checked while the command line is parsed, before anything starts) and the writing once the
run has ended (:mod:`dfrl.experiments.driver.results.tensorboard`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

from dfrl.experiments.driver.results import Results


class _TensorBoardFlag(argparse.Action):
    """``--tensorboard``: refused while it is parsed, so before anything starts, when
    ``tensorboardX`` is missing (exit 2 with the install command)."""

    def __init__(self, option_strings: list[str], dest: str, **kwargs: Any) -> None:
        super().__init__(option_strings, dest, nargs=0, default=False, **kwargs)

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: object,
        option_string: str | None = None,
    ) -> None:
        from dfrl.experiments.driver.results.tensorboard import TensorBoardMissing, require

        try:
            require()
        except TensorBoardMissing as exc:
            parser.error(f"{exc}; nothing was started")
        setattr(namespace, self.dest, True)


def add_tensorboard_argument(p: argparse.ArgumentParser) -> None:
    """Add ``--tensorboard``."""
    p.add_argument(
        "--tensorboard",
        action=_TensorBoardFlag,
        help="also write the scalars (rewards, collisions, epsilon, evaluations, "
        "shares, rounds) as TensorBoard event files into tensorboard/ of the "
        "results folder; needs pip install 'dfrl[tensorboard]'",
    )


def write_run_tensorboard(results: Results, args: argparse.Namespace, prog: str) -> bool:
    """With ``--tensorboard``: the run's scalars into ``tensorboard/`` of its results folder.
    False, said on stderr, when they could not be written (the run's own results stand, as
    when its plots fail)."""
    if not getattr(args, "tensorboard", False):
        return True
    from dfrl.experiments.driver.results.tensorboard import TENSORBOARD_DIR, write_run_scalars

    cfg = results.config
    robots = [r.id for r in cfg.robots] + [j.robot.id for j in cfg.joins]
    try:
        written = write_run_scalars(results.output_dir, cfg, robots)
    except (OSError, ValueError) as exc:
        print(f"{prog}: TensorBoard scalars not written: {exc}", file=sys.stderr)
        return False
    print(
        f"{prog}: {sum(written.values())} TensorBoard scalars in "
        f"{results.output_dir / TENSORBOARD_DIR}",
        file=sys.stderr,
    )
    return True


def write_train_tensorboard(out: Path, metrics: np.ndarray, prog: str) -> bool:
    """``dfrl train``'s scalars into ``OUT/tensorboard/``; False, said on stderr, when they
    could not be written."""
    from dfrl.experiments.driver.results.tensorboard import TENSORBOARD_DIR, write_train_scalars

    try:
        n = write_train_scalars(out, metrics)
    except (OSError, ValueError) as exc:
        print(f"{prog}: TensorBoard scalars not written: {exc}", file=sys.stderr)
        return False
    print(f"{prog}: {n} TensorBoard scalars in {out / TENSORBOARD_DIR}", file=sys.stderr)
    return True
