"""Shares applied on the robots, their matching to agent rounds, and ``rounds.csv``."""
from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable

from dfrl.experiments.driver.results.agent_log import AgentLog, RoundRecord


@dataclass(frozen=True)
class Share:
    """One applied ``set_q_table`` on a robot.

    ``round``, ``agent`` and ``epoch`` come from the agent's table write (contract K4); they
    are None in rows written without them (older nodes, writes not from a dFRL agent).
    """

    robot: str
    index: int
    iteration: int
    wall_time: float
    digest: str
    round: int | None = None
    agent: str | None = None
    epoch: int | None = None


def _opt_int(text: str | None) -> int | None:
    return int(text) if text not in (None, "") else None


def read_shares(path: str | Path) -> list[Share]:
    """Rows of a ``shares_<robot>.csv`` (missing file: none); a torn last row is left out."""
    p = Path(path)
    if not p.is_file():
        return []
    rows = []
    with open(p, newline="", encoding="utf-8") as fh:
        for r in csv.DictReader(fh):
            if not r.get("digest"):
                continue
            try:
                rows.append(Share(r["robot"], int(r["share_index"]), int(r["iteration"]),
                                  float(r["wall_time"]), r["digest"], _opt_int(r.get("round")),
                                  r.get("agent") or None, _opt_int(r.get("epoch"))))
            except (TypeError, ValueError):
                continue
    return rows


def match_shares(record: RoundRecord, shares: dict[str, list[Share]],
                 slack_s: float = 1e-4) -> dict[str, Share | None]:
    """For each robot the round visited, the share it received during that round.

    A share that names its agent and round (contract K4) belongs to that round: the one of
    the highest epoch (the last of them if several) is it; hosts' clocks play no part. Only
    for shares written without a round number (older nodes) the time is used: the agent
    stamps a round's start before its first read and its end after its last write, so the
    last such share whose wall time falls in ``[start, end + slack_s]`` is it (this needs
    the robots and the agent on one clock, i.e. one machine).
    """
    out: dict[str, Share | None] = {}
    for robot in record.visited:
        found = None
        for s in shares.get(robot, []):
            if s.round is not None:
                if s.round == record.round and s.agent in (None, record.agent) and \
                        (found is None or (s.epoch or 0) >= (found.epoch or 0)):
                    found = s
            elif record.start <= s.wall_time <= record.end + slack_s and \
                    (found is None or found.round is None):
                found = s
        out[robot] = found
    return out


ROUNDS_FIELDS = ("agent", "round", "start", "end", "duration_ms", "hops", "bytes", "method",
                 "visited", "skipped", "retries", "epoch", "error", "failed_method")


def skipped_text(record: RoundRecord) -> str:
    """The ``skipped`` cell: ``robot: reason`` per skipped stop, ``; ``-separated."""
    return "; ".join(f"{s.robot}: {' '.join(s.reason.split())}" for s in record.skipped)


def write_rounds_csv(path: str | Path, logs: Iterable[AgentLog], robots: list[str],
                     shares: dict[str, list[Share]]) -> list[dict[str, Any]]:
    """Write ``rounds.csv``; return its rows (``all_equal`` as a bool).

    Columns: :data:`ROUNDS_FIELDS` (``skipped``: the stops the agent could not visit and why,
    see :func:`skipped_text`; ``retries``, ``epoch`` as the agent logged them), then
    ``digest_<robot>`` for every robot (empty when the robot was not visited that round,
    ``missing`` when it was but no share was recorded), and ``all_equal``: every visited
    robot holds the same table right after the share.
    """
    rows: list[dict[str, Any]] = []
    for log in logs:
        for rec in log.rounds:
            matched = match_shares(rec, shares)
            row: dict[str, Any] = {
                "agent": rec.agent, "round": rec.round, "start": repr(rec.start),
                "end": repr(rec.end), "duration_ms": f"{rec.duration_ms:.3f}", "hops": rec.hops,
                "bytes": rec.bytes, "method": rec.method, "visited": " ".join(rec.visited),
                "skipped": skipped_text(rec), "retries": rec.retries, "epoch": rec.epoch,
                "error": " ".join(rec.error.split()), "failed_method": rec.failed_method,
            }
            digests = []
            for robot in robots:
                if robot not in matched:
                    row[f"digest_{robot}"] = ""
                else:
                    s = matched[robot]
                    row[f"digest_{robot}"] = s.digest if s is not None else "missing"
                    digests.append(s.digest if s is not None else None)
            row["all_equal"] = bool(digests) and None not in digests and len(set(digests)) == 1
            rows.append(row)
    rows.sort(key=lambda r: (r["agent"], int(r["round"]), float(r["start"])))
    fields = list(ROUNDS_FIELDS) + [f"digest_{r}" for r in robots] + ["all_equal"]
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=fields)
        w.writeheader()
        for row in rows:
            w.writerow({**row, "all_equal": str(row["all_equal"]).lower()})
    return rows


def read_rounds_csv(path: str | Path) -> list[dict[str, Any]]:
    """Rows of a ``rounds.csv`` as written by :func:`write_rounds_csv` (``all_equal`` a bool).

    Raises
    ------
    ValueError
        An ``all_equal`` cell is neither ``true`` nor ``false``.
    """
    rows = []
    with open(path, newline="", encoding="utf-8") as fh:
        for row in csv.DictReader(fh):
            flag = row.get("all_equal")
            if flag not in ("true", "false"):
                raise ValueError(f"{path}: all_equal is {flag!r} in round {row.get('round')}")
            rows.append({**row, "all_equal": flag == "true"})
    return rows


def count_equal(rows: Iterable[dict[str, Any]]) -> int:
    """Rounds after which every visited robot held the same table."""
    return sum(1 for row in rows if row["all_equal"])


def count_unverified(rows: Iterable[dict[str, Any]]) -> int:
    """Rounds not shown equal only because a visited robot's share record is missing (its
    ``shares_<robot>.csv`` lost with its host, say): the records there are all equal."""
    n = 0
    for row in rows:
        cells = [v for k, v in row.items() if k.startswith("digest_") and v]
        known = {v for v in cells if v != "missing"}
        if not row["all_equal"] and "missing" in cells and len(known) <= 1:
            n += 1
    return n
