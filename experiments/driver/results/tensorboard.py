"""TensorBoard scalars of a results folder (``dfrl run --tensorboard``, ``dfrl train
--tensorboard``), written from the folder's CSV files once the run has ended, so that the
event files hold exactly the values of the CSVs (float64, not TensorBoard's usual float32).

Layout (``tensorboard --logdir RESULTS/tensorboard``)::

    tensorboard/<robot>/events.out.tfevents.*    a run: one TensorBoard run per robot, so that
                                                 the robots' curves share each chart
    tensorboard/round_<agent>/events.out.tfevents.*   a run: the agent's rounds
    tensorboard/events.out.tfevents.*            dfrl train: its one robot

Tags of a robot (step: the robot's iteration):

========================================  ==============================================
``q_sum``, ``cumulative_reward``,         ``metrics.csv`` (a run) or ``metrics.csv`` of
``collisions``                            ``dfrl train``, every row
``epsilon``                               a run: the robot's exploration schedule (its
                                          ``trainer`` settings) after ``iteration``
                                          updates, one per iteration, as the learner
                                          computes it; ``dfrl train``: the ``epsilon``
                                          column of its ``metrics.csv``
``reward``, ``respawns``                  ``dfrl train`` only (its ``metrics.csv`` columns)
``eval/<arena>/<measure>``                ``live_evaluations.csv`` (``eval_every``):
                                          collisions_per_1000, progress, coverage,
                                          distance, mean_reward
``shares``                                ``shares_<robot>.csv``: shares applied so far,
                                          at the iteration of each share
========================================  ==============================================

Tags of an agent's rounds (step: the round), from ``rounds.csv``: ``duration_ms``, ``hops``,
``bytes``, ``visited`` and ``skipped`` (robots in the round and left out of it),
``all_equal`` (1 when every visited robot held the same table after the share) and
``failed`` (1 when the method failed). A table error is not written: a run does not
compute one (the studies do, ``experiments/science/reference.py``).

Needs ``tensorboardX`` (the optional extra ``dfrl[tensorboard]``): :func:`require` says so
before a run starts. Writing a folder again replaces its event files.
"""
from __future__ import annotations

import struct
import time
from pathlib import Path
from typing import Any, Iterable, Iterator

import numpy as np

from dfrl.experiments.driver.config import ExperimentConfig
from dfrl.experiments.driver.results.evaluations import EVALUATIONS_FILE, read_evaluations
from dfrl.experiments.driver.results.metrics import read_metrics
from dfrl.experiments.driver.results.rounds import read_rounds_csv, read_shares

__all__ = ["TENSORBOARD_DIR", "TensorBoardMissing", "read_scalars", "require",
           "write_run_scalars", "write_train_scalars"]

#: The folder of the event files inside a results folder.
TENSORBOARD_DIR = "tensorboard"

#: The measures of a live evaluation written as ``eval/<arena>/<measure>``.
EVAL_MEASURES = ("collisions_per_1000", "progress", "coverage", "distance", "mean_reward")

_EVENTS_GLOB = "events.out.tfevents.*"


class TensorBoardMissing(ImportError):
    """``tensorboardX`` is not installed."""


def require() -> None:
    """Raise :class:`TensorBoardMissing` (with the install command) unless ``tensorboardX``
    can be imported."""
    try:
        import tensorboardX  # noqa: F401
    except ImportError as exc:
        raise TensorBoardMissing(
            "--tensorboard needs tensorboardX, which is not installed: "
            "pip install 'dfrl[tensorboard]' (or pip install tensorboardX)") from exc


class _Events:
    """One event file being written: scalars as float64 tensors of the ``scalars`` plugin
    (what TensorBoard's scalar charts read; PyTorch's ``double_precision`` does the same)."""

    def __init__(self, folder: Path) -> None:
        require()
        from tensorboardX.event_file_writer import EventsWriter
        from tensorboardX.proto import event_pb2, summary_pb2, tensor_pb2, tensor_shape_pb2

        self._pb = (event_pb2, summary_pb2, tensor_pb2, tensor_shape_pb2)
        folder.mkdir(parents=True, exist_ok=True)
        for old in folder.glob(_EVENTS_GLOB):
            old.unlink()
        self._writer = EventsWriter(str(folder / "events"))
        self.path = Path(self._writer._file_name)   # noqa: SLF001 - the name it chose
        self.count = 0
        self._tags: set[str] = set()

    def scalars(self, step: int, values: dict[str, float]) -> None:
        """One event at ``step`` with a value per tag (non-finite values are refused)."""
        event_pb2, summary_pb2, tensor_pb2, shape_pb2 = self._pb
        meta = summary_pb2.SummaryMetadata(
            plugin_data=summary_pb2.SummaryMetadata.PluginData(plugin_name="scalars"))
        out = []
        for tag, v in values.items():
            v = float(v)
            if not np.isfinite(v):
                raise ValueError(f"{self.path.parent.name}: {tag} at step {step} is {v}")
            tensor = tensor_pb2.TensorProto(dtype="DT_DOUBLE", double_val=[v],
                                            tensor_shape=shape_pb2.TensorShapeProto())
            if tag in self._tags:
                out.append(summary_pb2.Summary.Value(tag=tag, tensor=tensor))
            else:   # the plugin is named once per tag and file, as TensorBoard's writers do
                self._tags.add(tag)
                out.append(summary_pb2.Summary.Value(tag=tag, tensor=tensor, metadata=meta))
        self._writer.write_event(event_pb2.Event(
            step=int(step), wall_time=time.time(), summary=summary_pb2.Summary(value=out)))
        self.count += len(out)

    def close(self) -> None:
        self._writer.close()


def _robot_epsilon(config: ExperimentConfig, robot: str) -> Any:
    """The exploration schedule robot ``robot`` ran with (as
    ``RobotConfig.trainer_config`` builds it), None for a robot not in ``config``."""
    from dfrl.robots.training import TrainerConfig

    spec = next((r for r in list(config.robots) + [j.robot for j in config.joins]
                 if r.id == robot), None)
    if spec is None:
        return None
    base = TrainerConfig().to_dict()
    base.update(config.trainer)
    base.update(arena=spec.arena, algo=spec.algo)
    return TrainerConfig.from_dict(base).learner.epsilon


def write_run_scalars(out: str | Path, config: ExperimentConfig,
                      robots: Iterable[str]) -> dict[str, int]:
    """Write the event files of a run's results folder ``out`` from its CSV files (what
    the end of the run wrote: ``metrics.csv``, ``live_evaluations.csv``, ``shares_*.csv``,
    ``rounds.csv``); return run name -> scalars written. ``robots``: the run's robots in
    order; a robot of ``metrics.csv`` not among them (one that joined while the run went on)
    comes after them, without ``epsilon`` when ``config`` does not name it.

    Raises
    ------
    TensorBoardMissing
    ValueError
        A value is not finite.
    """
    out = Path(out)
    root = out / TENSORBOARD_DIR
    metrics = read_metrics(out / "metrics.csv") if (out / "metrics.csv").is_file() else {}
    evals = (read_evaluations(out / EVALUATIONS_FILE)
             if (out / EVALUATIONS_FILE).is_file() else [])
    written: dict[str, int] = {}
    robots = list(robots)
    robots += [r for r in metrics if r not in robots]     # robots that joined while it ran
    for robot in robots:
        ev = _Events(root / robot)
        try:
            schedule = _robot_epsilon(config, robot)
            for row in metrics.get(robot, np.zeros(0, dtype=object)):
                it = int(row["iteration"])
                values = {"q_sum": row["q_sum"], "cumulative_reward": row["cumulative_reward"],
                          "collisions": row["collisions"]}
                if schedule is not None:
                    values["epsilon"] = schedule.value(it)
                ev.scalars(it, values)
            for r in evals:
                if r["robot"] == robot:
                    ev.scalars(r["iteration"], {f"eval/{r['arena']}/{m}": r[m]
                                                for m in EVAL_MEASURES})
            for n, share in enumerate(read_shares(out / f"shares_{robot}.csv"), start=1):
                ev.scalars(share.iteration, {"shares": n})
        finally:
            ev.close()
        written[robot] = ev.count
    rounds = read_rounds_csv(out / "rounds.csv") if (out / "rounds.csv").is_file() else []
    for agent in sorted({str(r["agent"]) for r in rounds}):
        ev = _Events(root / f"round_{agent}")
        try:
            for r in (r for r in rounds if str(r["agent"]) == agent):
                ev.scalars(int(r["round"]), _round_values(r))
        finally:
            ev.close()
        written[f"round_{agent}"] = ev.count
    return written


def _round_values(row: dict[str, Any]) -> dict[str, float]:
    """The scalars of one ``rounds.csv`` row (as :func:`read_rounds_csv` gives it); a row
    rebuilt from the shares has no duration, hops or bytes (empty cells: no scalar)."""
    values = {key: float(row[key]) for key in ("duration_ms", "hops", "bytes")
              if row.get(key) not in ("", None)}
    values["visited"] = float(len(str(row["visited"]).split()))
    skipped = str(row["skipped"]).strip()
    values["skipped"] = float(len(skipped.split("; ")) if skipped else 0)
    values["all_equal"] = 1.0 if row["all_equal"] else 0.0
    values["failed"] = 1.0 if str(row["error"]).strip() else 0.0
    return values


#: ``dfrl train``'s ``metrics.csv`` columns written as scalars.
TRAIN_TAGS = ("q_sum", "cumulative_reward", "collisions", "epsilon", "reward", "respawns")


def write_train_scalars(out: str | Path, metrics: np.ndarray) -> int:
    """Write the event file of a ``dfrl train`` folder ``out`` from its metrics (the
    structured array :func:`dfrl.robots.training.train` returns and writes as
    ``metrics.csv``); return the scalars written.

    Raises
    ------
    TensorBoardMissing
    ValueError
        A value is not finite.
    """
    ev = _Events(Path(out) / TENSORBOARD_DIR)
    try:
        for row in metrics:
            ev.scalars(int(row["iteration"]), {t: row[t] for t in TRAIN_TAGS})
    finally:
        ev.close()
    return ev.count


def _records(path: Path) -> Iterator[bytes]:
    """The records of a TFRecord file, each checked against its two masked CRC-32C sums."""
    from tensorboardX.record_writer import masked_crc32c

    data = path.read_bytes()
    pos = 0
    while pos < len(data):
        if pos + 12 > len(data):
            raise ValueError(f"{path}: torn record header at byte {pos}")
        header = data[pos:pos + 8]
        (length,), (crc,) = struct.unpack("<Q", header), struct.unpack("<I", data[pos + 8:pos + 12])
        if crc != masked_crc32c(header):
            raise ValueError(f"{path}: bad length checksum at byte {pos}")
        body = data[pos + 12:pos + 12 + length]
        end = pos + 12 + length
        if len(body) != length or end + 4 > len(data):
            raise ValueError(f"{path}: torn record at byte {pos}")
        if struct.unpack("<I", data[end:end + 4])[0] != masked_crc32c(body):
            raise ValueError(f"{path}: bad data checksum at byte {pos}")
        yield body
        pos = end + 4


def read_scalars(folder: str | Path) -> dict[str, list[tuple[int, float]]]:
    """The scalars of the event files in ``folder`` (one TensorBoard run): tag -> [(step,
    value)] in file order; double and float tensors and ``simple_value`` alike.

    Raises
    ------
    TensorBoardMissing
    ValueError
        No event file, or a torn or corrupted record.
    """
    require()
    from tensorboardX.proto import event_pb2

    files = sorted(Path(folder).glob(_EVENTS_GLOB))
    if not files:
        raise ValueError(f"{folder}: no event file")
    out: dict[str, list[tuple[int, float]]] = {}
    for path in files:
        for body in _records(path):
            event = event_pb2.Event.FromString(body)
            for v in event.summary.value:
                if v.HasField("tensor"):
                    vals = list(v.tensor.double_val) or list(v.tensor.float_val)
                    value = float(vals[0])
                else:
                    value = float(v.simple_value)
                out.setdefault(v.tag, []).append((int(event.step), value))
    return out
