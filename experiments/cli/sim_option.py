"""``--sim`` of ``dfrl speedup``, ``transfer-study``, ``hetero`` and ``sweep``: the simulator
a study runs on (:mod:`dfrl.experiments.science.studies.simulators`)."""

from __future__ import annotations

import argparse

from dfrl.experiments.science.studies.simulators import DEFAULT_SIM, SIMS


def add_sim_argument(p: argparse.ArgumentParser, note: str = "") -> None:
    """Add ``--sim`` (unset when not given: :func:`chosen_sim` gives the default)."""
    p.add_argument(
        "--sim",
        choices=SIMS,
        default=None,
        help="simulator: batched (many robots in compiled kernels, Q-learning and "
        "SARSA) or pybullet (the robots of dfrl run); recorded in the "
        f"outputs{note} (default: {DEFAULT_SIM})",
    )


def chosen_sim(args: argparse.Namespace) -> str:
    """The simulator ``--sim`` named, else the default."""
    return args.sim if args.sim is not None else DEFAULT_SIM
