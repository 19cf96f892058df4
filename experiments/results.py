"""The results folder of a federated experiment: reading the pieces, writing the tables.

Layout (see ``experiments/README.md``)::

    config.json            the experiment config (ExperimentConfig.to_dict)
    nodes.json             robots' addresses, the agents and their itineraries
    metrics.csv            robot, iteration, q_sum, cumulative_reward, collisions (all robots)
    rounds.csv             one row per agent round: times, hops, bytes, method, a digest per
                           robot right after the share, all_equal
    q_sum.png, cumulative_reward.png, curves.png
    summary.md
    metrics_<robot>.csv    per-robot metrics, written by the node while it runs
    shares_<robot>.csv     per-robot applied shares (index, iteration, time, sha256)
    rounds_<agent>.log     the agent's log: round(...) and finished(...) Prolog facts
    nodes/<robot>.json     node configs; logs/<robot>.out|.err, logs/launch_<agent>.*
    tables/<robot>.npy     final tables (robots.tables format)
"""
from __future__ import annotations

import csv
import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

import numpy as np

# -- a small reader for the agent's log facts --------------------------------------------------
_TOKEN = re.compile(r"""
    \s*(?:
      (?P<float>[-+]?\d+\.\d*Inf|[-+]?1\.5NaN|[-+]?\d+\.\d+(?:[eE][-+]?\d+)?|[-+]?\d+[eE][-+]?\d+)
    | (?P<int>[-+]?\d+)
    | (?P<qatom>'(?:[^'\\]|\\.|'')*')
    | (?P<string>"(?:[^"\\]|\\.)*")
    | (?P<atom>[a-z][A-Za-z0-9_]*|[-+*/\\^<>=~:.?@#&$]+|\[\]|\{\}|!|;)
    | (?P<var>[A-Z_][A-Za-z0-9_]*)
    | (?P<punct>[(),\[\]|{}])
    )""", re.VERBOSE)


@dataclass(frozen=True)
class Fact:
    """A compound term read from a log line: ``name(args...)``."""

    name: str
    args: tuple[Any, ...]


class _Parser:
    def __init__(self, text: str) -> None:
        self.tokens: list[tuple[str, str]] = []
        pos = 0
        text = text.strip()
        if text.endswith("."):
            text = text[:-1]
        while pos < len(text):
            m = _TOKEN.match(text, pos)
            if m is None or m.end() == pos:
                if text[pos:].strip() == "":
                    break
                raise ValueError(f"cannot read term at {text[pos:pos + 20]!r}")
            kind = m.lastgroup
            self.tokens.append((kind, m.group(kind)))
            pos = m.end()
        self.i = 0

    def peek(self) -> tuple[str, str] | None:
        return self.tokens[self.i] if self.i < len(self.tokens) else None

    def take(self) -> tuple[str, str]:
        tok = self.peek()
        if tok is None:
            raise ValueError("unexpected end of term")
        self.i += 1
        return tok

    def expect(self, value: str) -> None:
        kind, v = self.take()
        if v != value:
            raise ValueError(f"expected {value!r}, got {v!r}")

    def term(self) -> Any:
        kind, v = self.take()
        if kind == "float":
            if "Inf" in v:
                return float("-inf") if v.startswith("-") else float("inf")
            if "NaN" in v:
                return float("nan")
            return float(v)
        if kind == "int":
            return int(v)
        if kind == "string":
            return v[1:-1].encode("utf-8").decode("unicode_escape")
        if kind == "var":
            return None
        if kind == "punct" and v == "[":
            items: list[Any] = []
            if self.peek() == ("punct", "]"):
                self.take()
                return items
            while True:
                items.append(self.term())
                kind2, v2 = self.take()
                if v2 == "]":
                    return items
                if v2 == "|":
                    self.term()
                    self.expect("]")
                    return items
                if v2 != ",":
                    raise ValueError(f"bad list separator {v2!r}")
        if kind == "punct" and v == "(":
            inner = self.term()
            while self.peek() == ("punct", ","):
                self.take()
                inner = (inner, self.term()) if not isinstance(inner, tuple) else inner + (self.term(),)
            self.expect(")")
            return inner
        if kind in ("atom", "qatom"):
            name = v if kind == "atom" else v[1:-1].replace("''", "'").replace("\\'", "'")
            if name == "[]":
                return []
            if self.peek() == ("punct", "("):
                self.take()
                args = [self.term()]
                while self.peek() == ("punct", ","):
                    self.take()
                    args.append(self.term())
                self.expect(")")
                return Fact(name, tuple(args))
            return name
        raise ValueError(f"unexpected token {v!r}")


def parse_fact(line: str) -> Any:
    """Read one Prolog term written with ``~k.`` (atoms, numbers, strings, lists, compounds).

    >>> parse_fact("round(1, 1.5, 2.0, 2, 4860, average, [r1, r2]).")
    Fact(name='round', args=(1, 1.5, 2.0, 2, 4860, 'average', ['r1', 'r2']))
    """
    p = _Parser(line)
    term = p.term()
    if p.peek() is not None:
        raise ValueError(f"trailing text after term in {line!r}")
    return term


@dataclass(frozen=True)
class RoundRecord:
    """One ``round(Round, Start, End, Hops, Bytes, Method, Visited)`` line of an agent log."""

    agent: str
    round: int
    start: float
    end: float
    hops: int
    bytes: int
    method: str
    visited: tuple[str, ...]

    @property
    def duration_ms(self) -> float:
        return (self.end - self.start) * 1000.0


@dataclass
class AgentLog:
    """What an agent's rounds log holds so far."""

    agent: str
    rounds: list[RoundRecord] = field(default_factory=list)
    finished: int | None = None
    aborted: list[str] = field(default_factory=list)
    unreadable: list[str] = field(default_factory=list)


def read_rounds_log(path: str | Path, agent: str) -> AgentLog:
    """Parse an agent's rounds log (missing file: empty log)."""
    log = AgentLog(agent)
    p = Path(path)
    if not p.is_file():
        return log
    for line in p.read_text(encoding="utf-8", errors="replace").splitlines():
        if not line.strip():
            continue
        if line.startswith("aborted("):
            log.aborted.append(line)
            continue
        try:
            term = parse_fact(line)
        except ValueError:
            log.unreadable.append(line)
            continue
        if isinstance(term, Fact) and term.name == "round" and len(term.args) == 7:
            r, s, e, hops, nbytes, method, visited = term.args
            log.rounds.append(RoundRecord(agent, int(r), float(s), float(e), int(hops), int(nbytes),
                                          str(method), tuple(str(v) for v in visited)))
        elif isinstance(term, Fact) and term.name == "finished":
            log.finished = int(term.args[0])
        elif isinstance(term, Fact) and term.name == "aborted":
            log.aborted.append(line)
        else:
            log.unreadable.append(line)
    return log


# -- shares and metrics -------------------------------------------------------------------------
@dataclass(frozen=True)
class Share:
    """One applied ``set_q_table`` on a robot."""

    robot: str
    index: int
    iteration: int
    wall_time: float
    digest: str


def read_shares(path: str | Path) -> list[Share]:
    """Rows of a ``shares_<robot>.csv`` (missing file: none)."""
    p = Path(path)
    if not p.is_file():
        return []
    with open(p, newline="", encoding="utf-8") as fh:
        return [Share(r["robot"], int(r["share_index"]), int(r["iteration"]), float(r["wall_time"]),
                      r["digest"]) for r in csv.DictReader(fh) if r.get("digest")]


def match_shares(record: RoundRecord, shares: dict[str, list[Share]],
                 slack_s: float = 1e-4) -> dict[str, Share | None]:
    """For each robot the round visited, the share it received during that round.

    The agent writes every visited robot once per round, after the round's start and before
    its end (both taken by the agent with the same clock as the robots; a robot stamps its
    share before replying, the agent stamps the end after the last reply): the last share
    whose wall time falls in ``[start, end + slack_s]`` is it.
    """
    out: dict[str, Share | None] = {}
    for robot in record.visited:
        found = None
        for s in shares.get(robot, []):
            if record.start <= s.wall_time <= record.end + slack_s:
                found = s
        out[robot] = found
    return out


ROUNDS_FIELDS = ("agent", "round", "start", "end", "duration_ms", "hops", "bytes", "method",
                 "visited")


def write_rounds_csv(path: str | Path, logs: Iterable[AgentLog], robots: list[str],
                     shares: dict[str, list[Share]]) -> list[dict[str, Any]]:
    """Write ``rounds.csv``; return its rows.

    Columns: :data:`ROUNDS_FIELDS`, then ``digest_<robot>`` for every robot (empty when the
    robot was not visited that round, ``missing`` when it was but no share was recorded), and
    ``all_equal``: every visited robot holds the same table right after the share.
    """
    rows: list[dict[str, Any]] = []
    for log in logs:
        for rec in log.rounds:
            matched = match_shares(rec, shares)
            row: dict[str, Any] = {
                "agent": rec.agent, "round": rec.round, "start": repr(rec.start),
                "end": repr(rec.end), "duration_ms": f"{rec.duration_ms:.3f}", "hops": rec.hops,
                "bytes": rec.bytes, "method": rec.method, "visited": " ".join(rec.visited),
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
    rows.sort(key=lambda r: (float(r["start"]), r["agent"]))
    fields = list(ROUNDS_FIELDS) + [f"digest_{r}" for r in robots] + ["all_equal"]
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=fields)
        w.writeheader()
        for row in rows:
            w.writerow({**row, "all_equal": str(row["all_equal"]).lower()})
    return rows


METRICS_FIELDS = ("robot", "iteration", "q_sum", "cumulative_reward", "collisions")


def merge_metrics(out_dir: str | Path, robots: list[str]) -> Path:
    """Concatenate the ``metrics_<robot>.csv`` files into ``metrics.csv`` (robot order kept)."""
    out = Path(out_dir)
    target = out / "metrics.csv"
    with open(target, "w", newline="", encoding="utf-8") as dst:
        dst.write(",".join(METRICS_FIELDS) + "\n")
        for robot in robots:
            src = out / f"metrics_{robot}.csv"
            if not src.is_file():
                continue
            with open(src, encoding="utf-8") as fh:
                next(fh, None)
                for line in fh:
                    if line.count(",") == 4 and line.endswith("\n"):   # skip a torn last line
                        dst.write(line)
    return target


_CURVE_DTYPE = np.dtype([("iteration", np.int64), ("q_sum", np.float64),
                         ("cumulative_reward", np.float64), ("collisions", np.int64)])


def read_metrics(path: str | Path) -> dict[str, np.ndarray]:
    """``metrics.csv`` (or a per-robot file) -> robot -> structured array (iteration, q_sum,
    cumulative_reward, collisions), in file order."""
    rows: dict[str, list[tuple[int, float, float, int]]] = {}
    with open(path, newline="", encoding="utf-8") as fh:
        for r in csv.DictReader(fh):
            rows.setdefault(r["robot"], []).append(
                (int(r["iteration"]), float(r["q_sum"]), float(r["cumulative_reward"]),
                 int(r["collisions"])))
    return {robot: np.array(v, dtype=_CURVE_DTYPE) for robot, v in rows.items()}


def read_json(path: str | Path) -> Any:
    """A JSON file's content."""
    return json.loads(Path(path).read_text(encoding="utf-8"))


def write_json(path: str | Path, data: Any) -> Path:
    """Write JSON (indented, trailing newline) atomically enough for readers polling it."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_suffix(p.suffix + ".tmp")
    tmp.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    tmp.replace(p)
    return p
