"""What the agents carried, as the robots recorded it: the distillation residual of every grid
write a function learner absorbed (``distillation.csv``) and the weight every robot had in
each round of a FedAvg of parameters (``fedavg_weights.csv``).

Both files are written at the end of a run from the robots' own records
(:mod:`dfrl.experiments.robot_host.share_notes`): ``distillation_<robot>.csv`` (one row per
distilled write, with its round and agent) and ``weights_<robot>.csv`` (one row per read of
the robot's parameters, with the samples it reported). A read names no round: the weight of a
robot in round N of an agent is the samples of its last read before its write of that round
(:func:`fedavg_weights`; in a round the agent reads every robot before it writes any).

``distillation.csv`` (:data:`DISTILLATION_COLUMNS`): robot, agent, round, epoch, iteration,
steps, rms_before, rms_after, max_after, seconds; sorted by agent, round, robot.
``fedavg_weights.csv`` (:data:`WEIGHT_COLUMNS`): agent, round, robot, samples, weight (the
robot's share of the round's samples; empty when the round's samples sum to 0).
"""
from __future__ import annotations

import csv
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from dfrl.experiments.driver.results.rounds import Share

__all__ = ["DISTILLATION_COLUMNS", "WEIGHT_COLUMNS", "Distilled", "Weight",
           "fedavg_weights", "read_distillations", "write_distillation_csv",
           "write_weights_csv"]

DISTILLATION_COLUMNS: tuple[str, ...] = ("robot", "agent", "round", "epoch", "iteration",
                                         "steps", "rms_before", "rms_after", "max_after",
                                         "seconds")
WEIGHT_COLUMNS: tuple[str, ...] = ("agent", "round", "robot", "samples", "weight")


@dataclass(frozen=True)
class Distilled:
    """One grid write a function learner absorbed by distillation (RMS: root mean squared
    residual of its Q-function at the grid's points against the written table)."""

    robot: str
    agent: str
    round: int
    epoch: int
    iteration: int
    steps: int
    rms_before: float
    rms_after: float
    max_after: float
    seconds: float


@dataclass(frozen=True)
class Weight:
    """A robot's weight in one round of an agent's FedAvg: its samples when read, and their
    share of the round's (None: the round's samples sum to 0)."""

    agent: str
    round: int
    robot: str
    samples: int
    weight: float | None


def _rows(path: Path) -> list[dict[str, str]]:
    """The complete rows of a robot's CSV (a torn last row is left out; no file: none)."""
    if not path.is_file():
        return []
    with open(path, newline="", encoding="utf-8") as fh:
        return [r for r in csv.DictReader(fh) if None not in r.values() and None not in r]


def read_distillations(out: Path, robots: Iterable[str]) -> list[Distilled]:
    """The distilled writes the robots recorded (``distillation_<robot>.csv``), sorted by
    agent, round and robot; a robot that wrote one twice (resumed) keeps its later row.

    Raises
    ------
    ValueError
        A row that does not parse, named with its file and line.
    """
    found: dict[tuple[str, int, str], Distilled] = {}
    for rid in robots:
        path = Path(out) / f"distillation_{rid}.csv"
        for line, r in enumerate(_rows(path), start=2):
            try:
                d = Distilled(r["robot"], r["agent"], int(r["round"]), int(r["epoch"] or 0),
                              int(r["iteration"]), int(r["steps"]), float(r["rms_before"]),
                              float(r["rms_after"]), float(r["max_after"]), float(r["seconds"]))
            except (KeyError, ValueError) as exc:
                raise ValueError(f"{path}:{line}: not a distillation row ({exc})") from exc
            found[(d.agent, d.round, d.robot)] = d
    return [found[k] for k in sorted(found)]


def write_distillation_csv(path: Path, rows: Sequence[Distilled]) -> Path:
    """Write ``distillation.csv`` (see the module doc)."""
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(DISTILLATION_COLUMNS)
        for d in rows:
            w.writerow((d.robot, d.agent, d.round, d.epoch, d.iteration, d.steps,
                        repr(d.rms_before), repr(d.rms_after), repr(d.max_after),
                        repr(d.seconds)))
    return path


def fedavg_weights(out: Path, shares: Mapping[str, Sequence[Share]]) -> list[Weight]:
    """Every robot's weight in every round of a FedAvg of parameters: for each write a robot
    recorded (``shares``, with its round and agent), the samples of the robot's last read
    (``weights_<robot>.csv``) before it; writes to robots that recorded no read (tabular
    robots: their agents carry tables) are left out. Sorted by agent, round and robot.

    Raises
    ------
    ValueError
        A row of a weights file that does not parse, named with its file and line.
    """
    picked: dict[tuple[str, int, str], int] = {}
    for rid, rows in shares.items():
        path = Path(out) / f"weights_{rid}.csv"
        reads: list[tuple[float, int]] = []
        for line, r in enumerate(_rows(path), start=2):
            try:
                reads.append((float(r["wall_time"]), int(r["samples"])))
            except (KeyError, ValueError) as exc:
                raise ValueError(f"{path}:{line}: not a weights row ({exc})") from exc
        if not reads:
            continue
        for s in rows:
            if s.round is None or s.agent is None:
                continue
            before = [samples for t, samples in reads if t <= s.wall_time]
            if before:
                picked[(s.agent, s.round, rid)] = before[-1]
    totals: dict[tuple[str, int], int] = {}
    for (agent, n, _), samples in picked.items():
        totals[(agent, n)] = totals.get((agent, n), 0) + samples
    out_rows = []
    for (agent, n, rid) in sorted(picked):
        total = totals[(agent, n)]
        samples = picked[(agent, n, rid)]
        out_rows.append(Weight(agent, n, rid, samples, samples / total if total else None))
    return out_rows


def write_weights_csv(path: Path, rows: Sequence[Weight]) -> Path:
    """Write ``fedavg_weights.csv`` (see the module doc)."""
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.writer(fh)
        w.writerow(WEIGHT_COLUMNS)
        for x in rows:
            w.writerow((x.agent, x.round, x.robot, x.samples,
                        "" if x.weight is None else repr(x.weight)))
    return path
