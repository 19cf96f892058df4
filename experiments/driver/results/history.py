"""A history checker for the table writes robots recorded (after Jepsen's checkers): did the
agents' writes, as the robots applied them, keep the federation's rules?

The history is what every robot appended to its ``shares_<robot>.csv``: one row per table
write it applied, in the order it applied them, each naming the write's ``agent``, ``round``
and ``epoch`` (contract K4). Hosts' clocks differ, so no check compares wall times; each
uses only round numbers, epochs, digests and the order of one robot's own file.

Checks, per agent (each broken rule is one :class:`Violation` of that kind):

``doubled_write``
    A robot applied more than one write of the same round (two copies of the agent, or a
    copy and its replacement, both wrote it).
``epoch_regressed``
    A robot applied a write of a lower epoch after one of a higher epoch (its file order
    is the order it applied them in).
``stale_epoch``
    A write of round N with epoch E while some robot recorded a write of an earlier round
    M < N with a higher epoch E' > E: epoch E' had taken over by round M (an agent gets a
    new epoch only when it is resurrected, and goes on from the round it was resurrected
    in), so a copy of epoch E writing a later round is a superseded copy that kept working.
    The same round (M = N) is no violation here: a resurrection may finish a round its lower
    epoch began (the robots that copy wrote before it was lost keep their writes); two
    copies at odds in one round show up as ``doubled_write`` where both wrote one robot and
    as ``split_round`` where they wrote different tables.
``split_round``
    The robots written in a round do not all hold the same table: each robot's write of the
    round (the one of the highest epoch, the last of them if several, as ``rounds.csv``
    counts it) has its digest, and these differ. Robots whose table after a write is not the
    aggregate itself are left out of this check (``approximate``: in a grid federation a
    function learner absorbs the aggregate by distillation and records its own Q-function
    at the grid, :func:`approximate_robots`).

Rows without an agent or a round (a table set by hand, an older node) are not checked; they
are counted in :attr:`HistoryVerdict.ignored`.

:func:`check_shares` checks rows in memory; :func:`check_history` reads a results folder
(strictly: a malformed row is a :class:`HistoryInputError` naming its file and line, only a
torn last line, one the robot did not finish writing, is left out).
"""
from __future__ import annotations

import csv
import io
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import Any

from dfrl.experiments.driver.config_check import GRID
from dfrl.experiments.driver.results.files import read_json
from dfrl.experiments.driver.results.rounds import Share, counted_writes
from dfrl.experiments.errors import ExperimentError

__all__ = ["HistoryInputError", "HistoryVerdict", "Violation", "ViolationKind",
           "approximate_robots", "check_history", "check_shares", "read_history",
           "read_history_file"]

#: Columns a shares file must have (``round``, ``agent`` and ``epoch`` may be missing: an
#: older node's file, whose rows are then all ignored).
REQUIRED_FIELDS = ("robot", "share_index", "iteration", "wall_time", "digest")


class ViolationKind(str, Enum):
    """The rules a history can break (see the module doc)."""

    DOUBLED_WRITE = "doubled_write"
    EPOCH_REGRESSED = "epoch_regressed"
    STALE_EPOCH = "stale_epoch"
    SPLIT_ROUND = "split_round"


@dataclass(frozen=True)
class Violation:
    """One broken rule: which, of which agent, at which robot(s), in which round, in words."""

    kind: ViolationKind
    agent: str
    robots: tuple[str, ...]
    round: int
    detail: str

    def to_json(self) -> dict[str, Any]:
        """The violation as a JSON-ready dict."""
        return {"kind": self.kind.value, "agent": self.agent, "robots": list(self.robots),
                "round": self.round, "detail": self.detail}


@dataclass(frozen=True)
class HistoryVerdict:
    """What :func:`check_shares` found.

    Attributes
    ----------
    violations : tuple of Violation
        In the order: agent, kind (as :class:`ViolationKind` lists them), round.
    writes : int
        Rows checked (those with an agent and a round).
    ignored : int
        Rows without an agent or a round (not checked).
    rounds : int
        Distinct (agent, round) pairs written.
    robots : int
        Robots with at least one row.
    agents : tuple of str
        The agents whose writes were checked.
    torn : int
        Torn last lines left out (:func:`check_history` only).
    """

    violations: tuple[Violation, ...]
    writes: int
    ignored: int
    rounds: int
    robots: int
    agents: tuple[str, ...] = ()
    torn: int = 0

    @property
    def ok(self) -> bool:
        """No rule broken."""
        return not self.violations

    def counts(self) -> dict[str, int]:
        """Violations per kind (every kind listed, zeros included)."""
        return {k.value: sum(1 for v in self.violations if v.kind is k) for k in ViolationKind}

    def text(self, shown: int = 5) -> str:
        """The verdict in one paragraph (for ``summary.md`` and the command line): what was
        checked, then ok or the violations per kind and the first ``shown`` of them."""
        what = (f"{self.writes} write(s) of {len(self.agents)} agent(s) in {self.rounds} "
                f"round(s) on {self.robots} robot(s) checked")
        extra = [f"{self.ignored} row(s) without agent or round not checked"] \
            if self.ignored else []
        if self.torn:
            extra.append(f"{self.torn} torn last line(s) left out")
        tail = f" ({'; '.join(extra)})" if extra else ""
        if self.ok:
            return (f"history ok: {what}{tail}; no doubled write, no epoch regressed, no stale "
                    f"epoch, no split round.")
        kinds = ", ".join(f"{n} {k}" for k, n in self.counts().items() if n)
        first = "; ".join(f"{v.kind.value}: {v.detail}" for v in self.violations[:shown])
        more = (f"; ... {len(self.violations) - shown} more"
                if len(self.violations) > shown else "")
        return (f"history VIOLATED: {what}{tail}; {len(self.violations)} violation(s) "
                f"({kinds}): {first}{more}.")

    def to_json(self) -> dict[str, Any]:
        """The verdict as a JSON-ready dict (``ok``, the counts, every violation)."""
        return {"ok": self.ok, "writes": self.writes, "ignored": self.ignored,
                "rounds": self.rounds, "robots": self.robots, "agents": list(self.agents),
                "torn": self.torn, "counts": self.counts(),
                "violations": [v.to_json() for v in self.violations]}


class HistoryInputError(ExperimentError):
    """A shares file the checker cannot read: the file, the line (1 = the header; None when
    the whole file is at fault) and why."""

    def __init__(self, path: Path, line: int | None, why: str) -> None:
        where = f"{path}:{line}" if line is not None else str(path)
        super().__init__(f"{where}: {why}")
        self.path = path
        self.line = line
        self.why = why


def _short(digest: str) -> str:
    """A digest's first 12 hex digits (enough to tell tables apart in a sentence)."""
    return digest[:12]


def _epoch(s: Share) -> int:
    """A write's epoch (a row without one: 0, as :func:`~.rounds.match_shares` counts it)."""
    return s.epoch if s.epoch is not None else 0


def check_shares(shares: Mapping[str, Sequence[Share]], torn: int = 0,
                 approximate: Collection[str] = ()) -> HistoryVerdict:
    """Check a history held in memory (see the module doc for the rules).

    Parameters
    ----------
    shares : mapping
        robot -> the rows of its ``shares_<robot>.csv`` in file order (the robot of a row is
        the key it is listed under).
    torn : int
        Torn last lines the reader left out, carried into the verdict.
    approximate : collection of str
        Robots left out of ``split_round`` (their table after a write is not the aggregate
        itself; see the module doc).
    """
    ignored = 0
    # agent -> robot -> its rows of that agent, in file order
    by_agent: dict[str, dict[str, list[Share]]] = {}
    robots = 0
    for robot, rows in shares.items():
        if rows:
            robots += 1
        for s in rows:
            if s.agent is None or s.round is None:
                ignored += 1
                continue
            by_agent.setdefault(s.agent, {}).setdefault(robot, []).append(s)
    violations: list[Violation] = []
    rounds = 0
    writes = 0
    for agent in sorted(by_agent):
        rows_of = by_agent[agent]
        writes += sum(len(rows) for rows in rows_of.values())
        rounds += len({s.round for rows in rows_of.values() for s in rows})
        found = (_doubled(agent, rows_of) + _regressed(agent, rows_of)
                 + _stale(agent, rows_of)
                 + _split(agent, {r: rows for r, rows in rows_of.items()
                                  if r not in approximate}))
        violations += sorted(found, key=lambda v: (list(ViolationKind).index(v.kind), v.round,
                                                   v.robots))
    return HistoryVerdict(tuple(violations), writes, ignored, rounds, robots,
                          tuple(sorted(by_agent)), torn)


def _doubled(agent: str, rows_of: dict[str, list[Share]]) -> list[Violation]:
    """Each robot's rounds it applied more than one write of."""
    out = []
    for robot, rows in rows_of.items():
        per_round: dict[int, list[Share]] = {}
        for s in rows:
            assert s.round is not None
            per_round.setdefault(s.round, []).append(s)
        for n, same in per_round.items():
            if len(same) > 1:
                digests = {s.digest for s in same}
                what = ("the same table" if len(digests) == 1 else
                        f"{len(digests)} different tables")
                writes = ", ".join(f"share {s.index} epoch {_epoch(s)} {_short(s.digest)}"
                                   for s in same)
                out.append(Violation(ViolationKind.DOUBLED_WRITE, agent, (robot,), n,
                                     f"{robot} applied {len(same)} writes of {agent} round {n}, "
                                     f"{what} ({writes})"))
    return out


def _regressed(agent: str, rows_of: dict[str, list[Share]]) -> list[Violation]:
    """Each write a robot applied after one of a higher epoch."""
    out = []
    for robot, rows in rows_of.items():
        top: Share | None = None
        for s in rows:
            if top is not None and _epoch(s) < _epoch(top):
                assert s.round is not None
                out.append(Violation(ViolationKind.EPOCH_REGRESSED, agent, (robot,), s.round,
                                     f"{robot} applied epoch {_epoch(s)} of {agent} (round "
                                     f"{s.round}, share {s.index}) after epoch {_epoch(top)} "
                                     f"(round {top.round}, share {top.index})"))
            elif top is None or _epoch(s) > _epoch(top):
                top = s
    return out


def _stale(agent: str, rows_of: dict[str, list[Share]]) -> list[Violation]:
    """Each write of a round later than one a higher epoch wrote first
    (the rule in the module doc: by round numbers, never by clocks)."""
    # epoch -> (the earliest round a robot recorded with it, that robot)
    first: dict[int, tuple[int, str]] = {}
    for robot, rows in rows_of.items():
        for s in rows:
            assert s.round is not None
            e = _epoch(s)
            if e not in first or (s.round, robot) < first[e]:
                first[e] = (s.round, robot)
    out = []
    for robot, rows in rows_of.items():
        for s in rows:
            assert s.round is not None
            e = _epoch(s)
            # the highest epoch that had taken over before this write's round
            over = [(e2, m, r) for e2, (m, r) in first.items() if e2 > e and m < s.round]
            if over:
                e2, m, by = max(over)
                out.append(Violation(ViolationKind.STALE_EPOCH, agent, (robot,), s.round,
                                     f"{robot} applied {agent} round {s.round} of epoch {e} "
                                     f"(share {s.index}), but epoch {e2} had written round {m} "
                                     f"already ({by})"))
    return out


def _split(agent: str, rows_of: dict[str, list[Share]]) -> list[Violation]:
    """Each round whose robots hold different tables after it."""
    counted = counted_writes(rows_of, agent)
    out = []
    for n, writes in counted.items():
        digests: dict[str, list[str]] = {}
        for robot, s in sorted(writes.items()):
            digests.setdefault(s.digest, []).append(robot)
        if len(digests) > 1:
            groups = "; ".join(f"{', '.join(rs)}: {_short(d)}" for d, rs in digests.items())
            out.append(Violation(ViolationKind.SPLIT_ROUND, agent, tuple(sorted(writes)), n,
                                 f"{agent} round {n} left {len(digests)} different tables "
                                 f"({groups})"))
    return out


def read_history_file(path: Path, robot: str) -> tuple[list[Share], int]:
    """The rows of one ``shares_<robot>.csv``, read strictly; returns (rows, torn last lines
    left out: 0 or 1). A missing file has no rows.

    Raises
    ------
    HistoryInputError
        The file cannot be read, lacks a column of :data:`REQUIRED_FIELDS`, or a row (not a
        torn last line: one without its line end) has the wrong number of cells, a number that
        is none, no digest, or names another robot.
    """
    if not path.exists():
        return [], 0
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise HistoryInputError(path, None, f"cannot be read: {exc}") from None
    lines = text.splitlines(keepends=True)
    torn = 0
    if lines and not lines[-1].endswith(("\n", "\r")):
        lines, torn = lines[:-1], 1            # the robot did not finish writing it
    if not lines:
        return [], torn
    reader = csv.reader(io.StringIO("".join(lines)))
    header = next(reader)
    missing = [f for f in REQUIRED_FIELDS if f not in header]
    if missing:
        raise HistoryInputError(path, 1, f"not a shares file: no column {', '.join(missing)} "
                                         f"(header: {','.join(header)})")
    col = {name: i for i, name in enumerate(header)}
    rows = []
    for cells in reader:
        if cells:
            rows.append(_share(path, reader.line_num, col, cells, robot))
    return rows, torn


def _share(path: Path, line: int, col: dict[str, int], cells: list[str], robot: str) -> Share:
    """Line ``line`` of ``path`` (its ``cells``; ``col``: column name -> index) as a share.

    Raises
    ------
    HistoryInputError
        See :func:`read_history_file`.
    """
    if len(cells) != len(col):
        raise HistoryInputError(path, line, f"{len(cells)} cells, the header has {len(col)}")

    def cell(name: str) -> str:
        return cells[col[name]] if name in col else ""

    def number(name: str, kind: type = int, optional: bool = False) -> Any:
        text = cell(name)
        if optional and text == "":
            return None
        try:
            return kind(text)
        except ValueError:
            raise HistoryInputError(path, line, f"{name} is {text!r}, not a number") from None

    if cell("robot") != robot:
        raise HistoryInputError(path, line, f"the row is of robot {cell('robot')!r}, the file "
                                            f"of {robot!r}")
    if not cell("digest"):
        raise HistoryInputError(path, line, "no digest")
    return Share(robot, number("share_index"), number("iteration"), number("wall_time", float),
                 cell("digest"), number("round", optional=True), cell("agent") or None,
                 number("epoch", optional=True))


def read_history(out_dir: Path,
                 robots: Sequence[str] | None = None) -> tuple[dict[str, list[Share]], int]:
    """The shares files of a results folder read strictly: (robot -> its rows, torn last
    lines left out). ``robots``: whose files to read (a missing file: no rows); default:
    every ``shares_*.csv`` of the folder.

    Raises
    ------
    HistoryInputError
        ``out_dir`` is no folder, holds no shares file (without ``robots``), or a file is
        malformed (:func:`read_history_file`).
    """
    out = Path(out_dir)
    if not out.is_dir():
        raise HistoryInputError(out, None, "no such folder")
    if robots is None:
        files = sorted(out.glob("shares_*.csv"))
        if not files:
            raise HistoryInputError(out, None, "no shares_<robot>.csv in this folder (not a "
                                               "results folder?)")
        robots = [f.stem[len("shares_"):] for f in files]
    shares: dict[str, list[Share]] = {}
    torn = 0
    for rid in robots:
        shares[rid], t = read_history_file(out / f"shares_{rid}.csv", rid)
        torn += t
    return shares, torn


def approximate_robots(out_dir: Path) -> set[str]:
    """The robots of a results folder whose table after a write is not the aggregate itself:
    in a grid federation (``config.json``), those with a function learner (their algorithm by
    the config's robots and joins, and by ``nodes.json`` for robots that joined by ``dfrl
    join``). None in any other folder."""
    from dfrl.robots.learners import is_tabular

    try:
        config = read_json(Path(out_dir) / "config.json")
    except (OSError, ValueError):
        return set()
    if not isinstance(config, dict) or config.get("federation") != GRID:
        return set()
    entries = list(config.get("robots") or [])
    entries += [j.get("robot") for j in config.get("joins") or [] if isinstance(j, dict)]
    try:
        entries += [{"id": n.get("robot"), "algo": n.get("algo")}
                    for n in read_json(Path(out_dir) / "nodes.json")["nodes"]]
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        pass
    out = set()
    for e in entries:
        if not isinstance(e, dict) or not isinstance(e.get("id"), str):
            continue
        try:
            if not is_tabular(str(e.get("algo") or "qlearning")):
                out.add(e["id"])
        except KeyError:
            continue
    return out


def check_history(out_dir: Path, robots: Sequence[str] | None = None) -> HistoryVerdict:
    """Check the ``shares_<robot>.csv`` files of a results folder (see the module doc; the
    robots of :func:`approximate_robots` are left out of ``split_round``).

    Parameters
    ----------
    out_dir : Path
        The results folder.
    robots : sequence of str, optional
        The robots whose files to read (a missing file: no rows); default: every
        ``shares_*.csv`` of the folder.

    Raises
    ------
    HistoryInputError
        See :func:`read_history`.
    """
    shares, torn = read_history(out_dir, robots)
    return check_shares(shares, torn, approximate_robots(out_dir))
