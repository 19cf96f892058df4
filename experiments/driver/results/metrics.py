"""``metrics.csv``: the robots' learning curves, one row per robot and iteration.

Columns (:data:`METRICS_FIELDS`)::

    robot, iteration
    q_sum                the sum of the robot's table (a function learner: of its parameters)
                         at the end of the iteration: after its update and after the shares
                         applied in that iteration
    cumulative_reward    reward summed over iterations 1 .. iteration
    collisions           collisions so far
    shared               shares the robot applied in that iteration (its rows of
                         ``shares_<robot>.csv`` with that iteration): 0, 1 at a share, more
                         when several landed in one iteration (late ones after its last)
    q_sum_before_share   the sum after the update, before those shares (what the robot's
                         ``metrics_<robot>.csv`` holds); empty when ``shared`` is 0

:func:`merge_metrics` builds it from each robot's ``metrics_<robot>.csv`` (a row per iteration,
written before any write of that iteration) and ``shares_<robot>.csv`` (each write's iteration
and the sum it left, ``q_sum``). The last row of a robot therefore holds the sum of the table it
ended with (``tables/<robot>.npy``).

Files written before this format (no ``shared`` column) have one more row for a robot at its
last iteration, the sum of its saved table after the last share. :func:`read_metrics` reads
both: such a row is folded into the row before it (its ``q_sum`` the row's, the row's
``q_sum`` its ``q_sum_before_share``, ``shared`` 1); their other shares are in the shares files
only (``shared`` 0 there). Any other repeated robot and iteration is a :class:`MetricsFormatError`.
"""
from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from dfrl.experiments.driver.results.tables import table_sum
from dfrl.experiments.errors import ExperimentError

__all__ = ["METRICS_FIELDS", "MetricsFormatError", "merge_metrics", "read_metrics"]

METRICS_FIELDS = ("robot", "iteration", "q_sum", "cumulative_reward", "collisions", "shared",
                  "q_sum_before_share")

#: The columns of a robot's own ``metrics_<robot>.csv`` (and of ``metrics.csv`` before
#: ``shared``); the first five of :data:`METRICS_FIELDS`.
_ROBOT_FIELDS = METRICS_FIELDS[:5]

_CURVE_DTYPE = np.dtype([("iteration", np.int64), ("q_sum", np.float64),
                         ("cumulative_reward", np.float64), ("collisions", np.int64),
                         ("shared", np.int64), ("q_sum_before_share", np.float64)])


class MetricsFormatError(ExperimentError, ValueError):
    """A metrics file :func:`read_metrics` cannot read as curves: the file, the line (1 = the
    header) and why. A :class:`ValueError` too, as a malformed number is."""

    def __init__(self, path: Path, line: int, why: str) -> None:
        super().__init__(f"{path}:{line}: {why}")
        self.path = path
        self.line = line
        self.why = why


def _whole_lines(path: Path) -> str:
    """The text of ``path`` without a torn last line (one without its line end)."""
    text = path.read_text(encoding="utf-8")
    if text and not text.endswith("\n"):
        text = text[:text.rfind("\n") + 1]
    return text


def _writes(out: Path, robot: str) -> dict[int, tuple[int, str]]:
    """iteration -> (writes applied in it, the sum the last of them left: text, "" when the
    row does not say) from ``shares_<robot>.csv``; unreadable rows and a torn last line are
    left out (the history checker reports them)."""
    path = out / f"shares_{robot}.csv"
    if not path.is_file():
        return {}
    found: dict[int, tuple[int, str]] = {}
    for r in csv.DictReader(io.StringIO(_whole_lines(path))):
        try:
            it = int(r["iteration"] or "")
            q = (r.get("q_sum") or "").strip()
            if q:
                float(q)
        except (KeyError, TypeError, ValueError):
            continue
        found[it] = (found.get(it, (0, ""))[0] + 1, q)
    return found


def _snapshot_sum(out: Path, robot: str, iteration: int) -> str:
    """The sum of the table (or parameters) the robot saved after its share at ``iteration``
    (``tables/history/<robot>_it<N>.npy``), as text; "" when there is none."""
    for kind in ("tables", "params"):
        p = out / kind / "history" / f"{robot}_it{iteration}.npy"
        if p.is_file():
            try:
                return repr(float(np.load(p, allow_pickle=False).sum()))
            except (OSError, ValueError, EOFError):
                return ""
    return ""


def _robot_rows(src: Path) -> list[list[str]]:
    """The whole rows of a ``metrics_<robot>.csv`` as cells, each iteration once and in
    order (a row whose iteration is not above the one before it is left out: the robot
    process writes none)."""
    rows: list[list[str]] = []
    last = 0
    for line in _whole_lines(src).splitlines()[1:]:
        cells = line.split(",")
        if len(cells) != len(_ROBOT_FIELDS):
            continue
        try:
            it = int(cells[1])
        except ValueError:
            continue
        if it > last:
            rows.append(cells)
            last = it
    return rows


def merge_metrics(out_dir: str | Path, robots: list[str]) -> Path:
    """Write ``metrics.csv`` from the ``metrics_<robot>.csv`` and ``shares_<robot>.csv`` files
    (robot order kept; columns: the module's docstring); return its path.

    A row of an iteration in which the robot applied writes takes ``q_sum`` from the last of
    them (its shares row's ``q_sum``; for a shares file without it, written by an older robot
    host: the saved table at the robot's last row, else the table it saved at that share,
    ``tables/history/``; else the learner's sum stays, with ``q_sum_before_share`` empty).
    Writes at an iteration without a metrics row (before the first) are in the shares file
    only.
    """
    out = Path(out_dir)
    target = out / "metrics.csv"
    with open(target, "w", newline="", encoding="utf-8") as dst:
        dst.write(",".join(METRICS_FIELDS) + "\n")
        for robot in robots:
            src = out / f"metrics_{robot}.csv"
            if not src.is_file():
                continue
            rows = _robot_rows(src)
            writes = _writes(out, robot)
            for n, cells in enumerate(rows):
                count, after = writes.get(int(cells[1]), (0, ""))
                if count and not after and n == len(rows) - 1:
                    final = table_sum(out, robot)
                    after = "" if final is None else repr(final)
                if count and not after:
                    after = _snapshot_sum(out, robot, int(cells[1]))
                before = ""
                if after:
                    before, cells = cells[2], [cells[0], cells[1], after, cells[3], cells[4]]
                dst.write(",".join([*cells, str(count), before]) + "\n")
    return target


def read_metrics(path: str | Path) -> dict[str, np.ndarray]:
    """``metrics.csv`` (or a robot's ``metrics_<robot>.csv``, or a ``metrics.csv`` of the older
    format: the module's docstring) -> robot -> structured array (iteration, q_sum,
    cumulative_reward, collisions, shared, q_sum_before_share: NaN when empty), one entry per
    iteration, in file order. A torn last line is left out.

    Raises
    ------
    MetricsFormatError
        A column is missing, a cell is not a number, or a robot and iteration repeat (other
        than an older file's last-share row).
    """
    path = Path(path)
    reader = csv.DictReader(io.StringIO(_whole_lines(path)))
    fields = reader.fieldnames or []
    if not fields:
        return {}                               # an empty file: no curves
    missing = [f for f in _ROBOT_FIELDS if f not in fields]
    if missing:
        raise MetricsFormatError(path, 1, f"no column {', '.join(missing)} "
                                          f"(header: {','.join(fields)})")
    new = "shared" in fields
    rows: dict[str, list[tuple[int, float, float, int, int, float]]] = {}
    seen: dict[str, set[int]] = {}
    for r in reader:
        line = reader.line_num
        try:
            it, q = int(r["iteration"]), float(r["q_sum"])
            cr, coll = float(r["cumulative_reward"]), int(r["collisions"])
            shared = int(r["shared"]) if new else 0
            before = float(r["q_sum_before_share"] or "nan") if new else float("nan")
        except (TypeError, ValueError) as exc:
            raise MetricsFormatError(path, line, f"not a row of numbers: {exc}") from None
        robot = r["robot"]
        cur = rows.setdefault(robot, [])
        if it in seen.setdefault(robot, set()):
            prev = cur[-1]
            if new or prev[0] != it or prev[4] or (prev[2], prev[3]) != (cr, coll):
                raise MetricsFormatError(path, line, f"robot {robot} iteration {it} appears "
                                                     "twice")
            # the older format's last-share row: the sum the robot ended with
            cur[-1] = (it, q, cr, coll, max(prev[4], 1), prev[1])
            continue
        seen[robot].add(it)
        cur.append((it, q, cr, coll, shared, before))
    return {robot: np.array(v, dtype=_CURVE_DTYPE) for robot, v in rows.items()}
