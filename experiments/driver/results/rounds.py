"""Shares applied on the robots, their matching to agent rounds, and ``rounds.csv``."""
from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

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


def match_shares(record: RoundRecord, shares: Mapping[str, Sequence[Share]],
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


def counted_writes(shares: Mapping[str, Sequence[Share]],
                   agent: str) -> dict[int, dict[str, Share]]:
    """round -> robot -> the write of ``agent``'s round the robot holds after it: of its
    writes of that round, the one of the highest epoch (the last of them if several), as
    :func:`~.rounds.match_shares` takes it. Writes without a round are left out."""
    out: dict[int, dict[str, Share]] = {}
    for robot, rows in shares.items():
        for s in rows:
            if s.agent != agent or s.round is None:
                continue
            held = out.setdefault(s.round, {}).get(robot)
            if held is None or (s.epoch or 0) >= (held.epoch or 0):
                out[s.round][robot] = s
    return out


def share_agents(shares: Mapping[str, Sequence[Share]]) -> list[str]:
    """The agents named by the shares' writes, sorted."""
    return sorted({s.agent for rows in shares.values() for s in rows
                   if s.agent is not None and s.round is not None})


ROUNDS_FIELDS = ("agent", "round", "start", "end", "duration_ms", "hops", "bytes", "method",
                 "visited", "skipped", "retries", "epoch", "error", "failed_method", "written",
                 "reconstructed", "note")


def skipped_text(record: RoundRecord, written: Iterable[str] = ()) -> str:
    """The ``skipped`` cell: ``robot: reason`` per skipped stop, ``; ``-separated, leaving
    out the robots in ``written`` (they recorded a write of the round)."""
    kept = set(written)
    return "; ".join(f"{s.robot}: {' '.join(s.reason.split())}" for s in record.skipped
                     if s.robot not in kept)


def _in_order(names: Iterable[str], robots: list[str]) -> list[str]:
    """``names`` in the run's robot order, any others after them, sorted."""
    got = set(names)
    return [r for r in robots if r in got] + sorted(got - set(robots))


def _digest_cells(row: dict[str, Any], robots: list[str], cells: dict[str, str]) -> None:
    """``digest_<robot>`` cells and ``all_equal`` from ``cells`` (robot -> digest or
    ``missing``; robots not in it: empty)."""
    for robot in robots:
        row[f"digest_{robot}"] = cells.get(robot, "")
    digests = list(cells.values())
    row["all_equal"] = bool(digests) and "missing" not in digests and len(set(digests)) == 1


def _logged_row(rec: RoundRecord, robots: list[str], shares: Mapping[str, Sequence[Share]],
                writes: Mapping[str, Share]) -> dict[str, Any]:
    """The row of a round the agent logged; ``writes``: robot -> its recorded write of the
    round (:func:`counted_writes`)."""
    matched = match_shares(rec, shares)
    extra = {r: s for r, s in writes.items() if r not in matched}
    skipped = {s.robot for s in rec.skipped}
    notes = [f"{r} logged skipped but recorded a write of this round: counted written"
             for r in _in_order(set(extra) & skipped, robots)]
    notes += [f"{r} not in the logged round but recorded a write of it: counted written"
              for r in _in_order(set(extra) - skipped, robots)]
    written = [r for r, s in matched.items() if s is not None] + list(extra)
    row: dict[str, Any] = {
        "agent": rec.agent, "round": rec.round, "start": repr(rec.start),
        "end": repr(rec.end), "duration_ms": f"{rec.duration_ms:.3f}", "hops": rec.hops,
        "bytes": rec.bytes, "method": rec.method, "visited": " ".join(rec.visited),
        "skipped": skipped_text(rec, extra), "retries": rec.retries, "epoch": rec.epoch,
        "error": " ".join(rec.error.split()), "failed_method": rec.failed_method,
        "written": " ".join(_in_order(written, robots)), "reconstructed": False,
        "note": "; ".join(notes),
    }
    cells = {r: (s.digest if s is not None else "missing") for r, s in matched.items()}
    cells.update({r: s.digest for r, s in extra.items()})
    _digest_cells(row, robots, cells)
    return row


def _rebuilt_row(agent: str, n: int, robots: list[str],
                 writes: Mapping[str, Share]) -> dict[str, Any]:
    """The row of round ``n`` the agent's log lacks, from the writes the robots recorded:
    the robots written, the epoch, the digests; start and end are the first and last write's
    wall times on the robots' clocks; what only the log knows (hops, bytes, method, duration)
    is left empty."""
    written = _in_order(writes, robots)
    times = [s.wall_time for s in writes.values()]
    row: dict[str, Any] = {
        "agent": agent, "round": n, "start": repr(min(times)), "end": repr(max(times)),
        "duration_ms": "", "hops": "", "bytes": "", "method": "", "visited": " ".join(written),
        "skipped": "", "retries": "", "epoch": max(s.epoch or 0 for s in writes.values()),
        "error": "", "failed_method": "", "written": " ".join(written), "reconstructed": True,
        "note": "not in the agent's log: rebuilt from the robots' shares (start, end: the "
                "robots' clocks)",
    }
    _digest_cells(row, robots, {r: s.digest for r, s in writes.items()})
    return row


def write_rounds_csv(path: str | Path, logs: Iterable[AgentLog], robots: list[str],
                     shares: Mapping[str, Sequence[Share]]) -> list[dict[str, Any]]:
    """Write ``rounds.csv``; return its rows (``all_equal`` and ``reconstructed`` as bools).

    Columns: :data:`ROUNDS_FIELDS` (``visited``, ``skipped``, ``retries``, ``epoch`` as the
    agent logged them, but a robot that recorded a write of the round is never listed
    skipped; ``written``: the robots that recorded a write of the round; ``reconstructed``:
    the round is not in the agent's log, its row was rebuilt from the shares; ``note``: where
    the shares and the log disagree), then ``digest_<robot>`` for every robot (empty when
    the robot was neither visited nor written that round, ``missing`` when it was visited
    but no share was recorded), and ``all_equal``: every robot visited or written holds the
    same table right after the share.
    """
    rows: list[dict[str, Any]] = []
    logged: set[str] = set()
    for log in logs:
        logged.add(log.agent)
        counted = counted_writes(shares, log.agent)
        for rec in log.rounds:
            rows.append(_logged_row(rec, robots, shares, counted.get(rec.round, {})))
        done = {rec.round for rec in log.rounds}
        rows += [_rebuilt_row(log.agent, n, robots, counted[n]) for n in counted if n not in done]
    for agent in share_agents(shares):
        if agent not in logged:             # no log of this agent at all
            rows += [_rebuilt_row(agent, n, robots, w)
                     for n, w in counted_writes(shares, agent).items()]
    rows.sort(key=lambda r: (r["agent"], int(r["round"]), float(r["start"])))
    fields = list(ROUNDS_FIELDS) + [f"digest_{r}" for r in robots] + ["all_equal"]
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=fields)
        w.writeheader()
        for row in rows:
            w.writerow({**row, "all_equal": str(row["all_equal"]).lower(),
                        "reconstructed": str(row["reconstructed"]).lower()})
    return rows


def read_rounds_csv(path: str | Path) -> list[dict[str, Any]]:
    """Rows of a ``rounds.csv`` as written by :func:`write_rounds_csv` (``all_equal`` and
    ``reconstructed`` bools; an older file without ``reconstructed``: False).

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
            rows.append({**row, "all_equal": flag == "true",
                         "reconstructed": row.get("reconstructed") == "true"})
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
