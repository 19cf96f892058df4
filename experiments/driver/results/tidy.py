"""The tidy tables of a results folder: ``tidy/steps.csv``, ``tidy/shares.csv`` and
``tidy/rounds.csv``, one long-format table per kind of observation, one row per key
(:data:`TIDY_KEYS`), every row naming its robot's algorithm, arena and agent, so that a table
loads in one line (``pandas.read_csv``, ``polars.read_csv(..., infer_schema_length=None)``)
and pivots on its key. They are written from the folder's other files at the end of a run
(:func:`write_tidy_tables`); the wide files (``metrics.csv``, ``rounds.csv`` with a digest
column per robot) stay for the plots and the summary.

``steps.csv``, key (robot, iteration): :data:`STEP_FIELDS`; the numbers of ``metrics.csv``
(:mod:`.metrics`) as text, unchanged, ``q_sum_before_share`` filled with ``q_sum`` where no
share was applied; ``round``: the round of the last write the robot applied at or before
the iteration (0 before its first); ``phase``: ``share`` when the robot applied a write in
that iteration, else ``learn``.

``shares.csv``, key (robot, share_index): :data:`SHARE_FIELDS`; the rows of every
``shares_<robot>.csv`` (round, agent and epoch: the write's own, empty for a write that did
not name them).

``rounds.csv``, key (agent, round, robot): :data:`ROUND_FIELDS`; one row per robot a round
of the wide ``rounds.csv`` names (visited, written or skipped), with the round's cells and
the robot's ``outcome``: ``written`` (it recorded a write of the round), ``skipped`` (the
agent skipped it; ``reason`` says why) or ``missing`` (visited, but no write recorded: an
aborted round, or a record lost with its host); ``digest`` the table the write left.
"""
from __future__ import annotations

import csv
import io
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from dfrl.experiments.driver.config import ExperimentConfig
from dfrl.experiments.driver.results.files import read_json
from dfrl.experiments.errors import ExperimentError

__all__ = ["ROUND_FIELDS", "SHARE_FIELDS", "STEP_FIELDS", "TIDY_DIR", "TIDY_KEYS", "TidyError",
           "RobotFacts", "robot_facts", "write_tidy_tables"]

#: The folder of the tidy tables inside a results folder.
TIDY_DIR = "tidy"
#: The columns every table starts with: who the row is about.
_WHO = ("robot", "algo", "arena", "agent")
STEP_FIELDS: tuple[str, ...] = (*_WHO, "iteration", "round", "phase", "q_sum",
                                "q_sum_before_share", "cumulative_reward", "collisions",
                                "shared")
SHARE_FIELDS: tuple[str, ...] = (*_WHO, "share_index", "iteration", "round", "epoch",
                                 "wall_time", "digest", "q_sum")
ROUND_FIELDS: tuple[str, ...] = ("agent", "round", "robot", "algo", "arena", "epoch", "method",
                                 "outcome", "digest", "reason", "all_equal", "reconstructed",
                                 "start", "end", "duration_ms")
#: table name -> the columns whose values are unique together in it.
TIDY_KEYS: dict[str, tuple[str, ...]] = {"steps": ("robot", "iteration"),
                                         "shares": ("robot", "share_index"),
                                         "rounds": ("agent", "round", "robot")}


class TidyError(ExperimentError, ValueError):
    """A tidy table could not be written: a key repeats, or an input is unreadable; the
    message names the file (and line)."""


@dataclass(frozen=True)
class RobotFacts:
    """What every row of a robot names: its algorithm, arena and agent ("" when unknown)."""

    algo: str = ""
    arena: str = ""
    agent: str = ""


#: A row of a table and where it comes from (``shares_r1.csv:4``: file and line).
Sourced = tuple[dict[str, str], str]


def _rows(path: Path) -> list[Sourced]:
    """The rows of a CSV file as text with their places, a torn last line (one without its
    line end) left out; no file: none."""
    if not path.is_file():
        return []
    text = path.read_text(encoding="utf-8")
    if text and not text.endswith("\n"):
        text = text[:text.rfind("\n") + 1]
    reader = csv.DictReader(io.StringIO(text))
    return [(row, f"{path.name}:{reader.line_num}") for row in reader]


def robot_facts(out: Path, config: ExperimentConfig, robots: Sequence[str],
                shares: dict[str, list[Sourced]]) -> dict[str, RobotFacts]:
    """robot -> its facts: algorithm and arena from the config's robots and joins, else
    ``nodes.json`` (a robot that joined by ``dfrl join``), else its node config
    (``nodes/<robot>.json``); its agent from the agents' itineraries in ``nodes.json``, else
    the agent named by most of its writes (``shares``: robot -> its ``shares_<robot>.csv``
    rows)."""
    known = {s.id: (s.algo, s.arena) for s in (*config.robots, *(j.robot for j in config.joins))}
    agents: dict[str, str] = {}
    try:
        info = read_json(out / "nodes.json")
        for n in info.get("nodes", []):
            known.setdefault(str(n["robot"]), (str(n.get("algo") or ""),
                                               str(n.get("arena") or "")))
        for a in info.get("agents", []):
            for stop in a.get("itinerary", []):
                agents.setdefault(str(stop["robot"]), str(a["name"]))
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        pass                                    # no nodes.json (a run that never started)
    facts: dict[str, RobotFacts] = {}
    for rid in robots:
        algo, arena = known.get(rid, ("", ""))
        if not algo:
            try:
                node = read_json(out / "nodes" / f"{rid}.json")
                algo, arena = str(node.get("algo") or ""), str(node.get("arena") or "")
            except (OSError, ValueError, AttributeError):
                pass
        agent = agents.get(rid, "")
        if not agent:
            named = [r["agent"] for r, _ in shares.get(rid, []) if r.get("agent")]
            agent = max(dict.fromkeys(named), key=named.count) if named else ""  # ties: first
        facts[rid] = RobotFacts(algo, arena, agent)
    return facts


def _check_unique(rows: Iterable[Sourced], key: tuple[str, ...], path: Path) -> None:
    """Raise :class:`TidyError` at the first row whose ``key`` repeats, naming both rows'
    places in the files they come from."""
    seen: dict[tuple[str, ...], str] = {}
    for row, where in rows:
        k = tuple(row[c] for c in key)
        if k in seen:
            raise TidyError(f"{path.parent.name}/{path.name}: {where}: "
                            f"{', '.join(f'{c} {v}' for c, v in zip(key, k))} as in "
                            f"{seen[k]}; the key ({', '.join(key)}) must be unique")
        seen[k] = where


def _write(path: Path, fields: tuple[str, ...], rows: list[Sourced],
           key: tuple[str, ...]) -> Path:
    """Write ``rows`` (keys unique, else :class:`TidyError` and no file) to ``path``."""
    _check_unique(rows, key, path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".csv.tmp")
    with open(tmp, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=fields, lineterminator="\n")
        w.writeheader()
        w.writerows(row for row, _ in rows)
    tmp.replace(path)
    return path


def _int(text: str | None) -> int | None:
    try:
        return int(text or "")
    except ValueError:
        return None


def _who(rid: str, f: RobotFacts) -> dict[str, str]:
    return {"robot": rid, "algo": f.algo, "arena": f.arena, "agent": f.agent}


def step_rows(out: Path, facts: dict[str, RobotFacts],
              shares: dict[str, list[Sourced]]) -> list[Sourced]:
    """The rows of ``steps.csv`` from ``metrics.csv`` and the robots' writes (``shares``)."""
    rounds: dict[str, list[tuple[int, int]]] = {}     # robot -> (iteration, round) of writes
    for rid, rows in shares.items():
        writes = [(_int(r.get("iteration")), _int(r.get("round"))) for r, _ in rows]
        # by iteration, the writes of one iteration in the order applied (the file's)
        rounds[rid] = sorted(((i, n) for i, n in writes if i is not None and n is not None),
                             key=lambda w: w[0])
    out_rows: list[Sourced] = []
    current: dict[str, tuple[int, int]] = {}          # robot -> (next write, its round)
    for row, where in _rows(out / "metrics.csv"):
        rid, it = row["robot"], _int(row["iteration"])
        if it is None:
            raise TidyError(f"{where}: iteration {row['iteration']!r} is not an integer")
        pos, rnd = current.get(rid, (0, 0))
        applied = rounds.get(rid, [])
        while pos < len(applied) and applied[pos][0] <= it:
            rnd = applied[pos][1]
            pos += 1
        current[rid] = (pos, rnd)
        shared = row.get("shared") or "0"
        cells = {"iteration": row["iteration"], "round": str(rnd),
                 "phase": "learn" if shared == "0" else "share", "q_sum": row["q_sum"],
                 "q_sum_before_share": row.get("q_sum_before_share") or row["q_sum"],
                 "cumulative_reward": row["cumulative_reward"],
                 "collisions": row["collisions"], "shared": shared}
        out_rows.append(({**_who(rid, facts.get(rid, RobotFacts())), **cells}, where))
    return out_rows


def share_rows(facts: dict[str, RobotFacts],
               shares: dict[str, list[Sourced]]) -> list[Sourced]:
    """The rows of ``shares.csv``: every write the robots recorded, robot by robot."""
    rows = []
    for rid, writes in shares.items():
        for w, where in writes:
            rows.append(({**_who(rid, facts.get(rid, RobotFacts())),
                          "agent": w.get("agent") or "",
                          **{k: w.get(k) or "" for k in SHARE_FIELDS[4:]}}, where))
    return rows


def _skips(text: str, robots: set[str]) -> dict[str, str]:
    """The ``skipped`` cell of a wide ``rounds.csv`` (``robot: reason; ...``) -> robot ->
    reason (a ``; `` not followed by a robot's name belongs to the reason)."""
    found: dict[str, str] = {}
    last = None
    for piece in text.split("; ") if text else []:
        name, sep, reason = piece.partition(": ")
        if sep and name in robots:
            found[name] = reason
            last = name
        elif last is not None:
            found[last] += "; " + piece
    return found


def round_rows(out: Path, robots: Sequence[str],
               facts: dict[str, RobotFacts]) -> list[Sourced]:
    """The rows of the tidy ``rounds.csv`` from the wide one: per round, its robots in the
    run's order (then any others, sorted)."""
    rows = []
    for r, where in _rows(out / "rounds.csv"):
        cells = {k.removeprefix("digest_"): v for k, v in r.items()
                 if k.startswith("digest_") and v}
        written = set((r.get("written") or "").split())
        named = set(cells) | written | set(robots)
        skips = _skips(r.get("skipped") or "", named)
        present = set(cells) | written | set(skips)
        order = [x for x in robots if x in present] + sorted(present - set(robots))
        for rid in order:
            outcome = ("written" if rid in written else "skipped" if rid in skips
                       else "missing")
            f = facts.get(rid, RobotFacts())
            digest = cells.get(rid, "")
            rows.append(({"agent": r["agent"], "round": r["round"], "robot": rid,
                          "algo": f.algo, "arena": f.arena, "epoch": r.get("epoch") or "",
                          "method": r.get("method") or "", "outcome": outcome,
                          "digest": "" if digest == "missing" else digest,
                          "reason": skips.get(rid, ""), "all_equal": r.get("all_equal") or "",
                          "reconstructed": r.get("reconstructed") or "",
                          "start": r.get("start") or "", "end": r.get("end") or "",
                          "duration_ms": r.get("duration_ms") or ""}, where))
    return rows


def write_tidy_tables(out: str | Path, config: ExperimentConfig,
                      robots: Sequence[str]) -> tuple[list[Path], list[str]]:
    """Write ``tidy/steps.csv``, ``tidy/shares.csv`` and ``tidy/rounds.csv`` from the
    folder's ``metrics.csv``, ``shares_<robot>.csv`` and ``rounds.csv`` (written first);
    return (the tables written, one line per table that could not be: why, its file named).
    A table whose key would repeat is not written."""
    out = Path(out)
    shares = {rid: _rows(out / f"shares_{rid}.csv") for rid in robots}
    shares = {rid: [(r, w) for r, w in rows if r.get("digest") and _int(r.get("share_index"))
                    is not None] for rid, rows in shares.items()}
    facts = robot_facts(out, config, robots, shares)
    folder = out / TIDY_DIR
    written: list[Path] = []
    problems: list[str] = []
    builders = {"steps": (STEP_FIELDS, lambda: step_rows(out, facts, shares)),
                "shares": (SHARE_FIELDS, lambda: share_rows(facts, shares)),
                "rounds": (ROUND_FIELDS, lambda: round_rows(out, robots, facts))}
    for name, (fields, build) in builders.items():
        path = folder / f"{name}.csv"
        try:
            written.append(_write(path, fields, build(), TIDY_KEYS[name]))
        except TidyError as exc:
            problems.append(f"tidy table not written: {exc}")
        except (OSError, KeyError, ValueError) as exc:
            problems.append(f"tidy table not written: {path}: {type(exc).__name__}: {exc}")
    return written, problems
