"""Checking configurations before anything starts: one schema for experiment, robot, join and
node configs, every problem reported at once with its key path.

:func:`check_experiment` and :func:`check_node` take the JSON form (a dict, as read from a
file) and return the list of problems, each a line such as
``robots[1].algo: unknown algorithm 'dqn'; known: qlearning, sarsa``; :class:`ConfigError`
carries such a list. What is checked: unknown keys, types (``"2000"`` is not an integer, a
bool is not a number), ranges, robot ids, ``HOST:PORT`` nodes, unique ids and nodes, known
algorithms and aggregation methods, the ``trainer`` fields, and (``resources=True``) that every
arena exists and parses (:func:`dfrl.arenas.load_arena`, whose errors name file and place).
"""
from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

#: Aggregation methods built into the agent; others are injected into a running experiment
#: with ``dfrl inject`` (an experiment config can only name these).
BUILTIN_METHODS: tuple[str, ...] = ("average", "max", "visit_average")

#: Keys a config file may carry that are not fields (notes for people).
COMMENT_KEYS = frozenset({"comment"})

_ROBOT_ID = re.compile(r"[a-z][a-z0-9_]*\Z")


class ConfigError(ValueError):
    """A configuration that cannot run; :attr:`problems` lists every problem, each with its key
    path (``robots[1].algo: ...``), :attr:`source` the file (or None)."""

    def __init__(self, problems: Sequence[str], source: str | None = None) -> None:
        self.problems = list(problems)
        self.source = source
        super().__init__(self.text())

    def text(self) -> str:
        prefix = f"{self.source}: " if self.source else ""
        return "\n".join(prefix + p for p in self.problems)


@dataclass(frozen=True)
class Rule:
    """What one key may hold: ``kind`` (``int``, ``float``, ``str``, ``bool``, ``dict``,
    ``list``), ``None`` allowed when ``nullable``, inclusive bounds ``low``/``high`` (``above``:
    strictly greater), ``choices`` (a function returning the known values) named ``what``;
    ``check`` (a function returning a problem or None) replaces the kind and bounds (a value of
    more than one kind, such as a token)."""

    kind: type
    nullable: bool = False
    low: float | None = None
    above: float | None = None
    high: float | None = None
    choices: Callable[[], Sequence[str]] | None = None
    what: str = "value"
    hint: str = ""
    check: Callable[[Any], str | None] | None = None


def _type_name(value: Any) -> str:
    return {bool: "a boolean", int: "an integer", float: "a number", str: "a string",
            list: "a list", dict: "an object", type(None): "null"}.get(type(value),
                                                                         type(value).__name__)


_EXPECT = {int: "an integer", float: "a number", str: "a string", bool: "true or false",
           dict: "an object", list: "a list"}


def check_value(path: str, value: Any, rule: Rule) -> list[str]:
    """Problems of ``value`` at ``path`` against ``rule`` (empty: fine)."""
    if value is None:
        return [] if rule.nullable else [f"{path}: must not be null"]
    if rule.check is not None:
        why = rule.check(value)
        return [] if why is None else [f"{path}: {why}"]
    ok = (isinstance(value, bool) if rule.kind is bool else
          isinstance(value, (int, float)) and not isinstance(value, bool) if rule.kind is float
          else isinstance(value, int) and not isinstance(value, bool) if rule.kind is int
          else isinstance(value, rule.kind))
    if not ok:
        return [f"{path}: expected {_EXPECT[rule.kind]}{' or null' if rule.nullable else ''}, "
                f"got {value!r} ({_type_name(value)})"]
    if rule.kind is float and not math.isfinite(value):
        return [f"{path}: must be a finite number, got {value!r}"]
    hint = f" ({rule.hint})" if rule.hint else ""
    if rule.low is not None and value < rule.low:
        return [f"{path}: must be >= {rule.low:g}, got {value!r}{hint}"]
    if rule.above is not None and value <= rule.above:
        return [f"{path}: must be > {rule.above:g}, got {value!r}{hint}"]
    if rule.high is not None and value > rule.high:
        return [f"{path}: must be <= {rule.high:g}, got {value!r}{hint}"]
    if rule.choices is not None:
        known = list(rule.choices())
        if value not in known:
            return [f"{path}: unknown {rule.what} {value!r}; known: {', '.join(known)}{hint}"]
    return []


def check_keys(path: str, data: Any, rules: dict[str, Rule], required: Sequence[str] = (),
               extra: frozenset[str] = frozenset()) -> list[str]:
    """Problems of object ``data``: not an object, unknown or missing keys, bad values."""
    if not isinstance(data, dict):
        return [f"{path or 'config'}: expected an object, got {data!r} ({_type_name(data)})"]
    out = []
    dot = f"{path}." if path else ""
    for key in data:
        if key not in rules and key not in extra:
            near = [k for k in rules if _close(str(key), k)]
            also = f"; did you mean {near[0]!r}?" if near else ""
            out.append(f"{dot}{key}: unknown key{also} (known: {', '.join(sorted(rules))})")
    for key in required:
        if key not in data:
            out.append(f"{dot}{key}: missing (required)")
    for key, rule in rules.items():
        if key in data:
            out += check_value(f"{dot}{key}", data[key], rule)
    return out


def _close(a: str, b: str) -> bool:
    """``a`` looks like a misspelling of ``b`` (prefix of one another, or one edit apart)."""
    a, b = a.lower(), b.lower()
    if a == b or (len(a) > 2 and (a.startswith(b) or b.startswith(a))):
        return True
    if abs(len(a) - len(b)) > 1:
        return False
    return sum(x != y for x, y in zip(a, b)) + abs(len(a) - len(b)) <= 1


def known_algorithms() -> list[str]:
    from dfrl.robots.learners import LEARNERS

    return sorted(LEARNERS)


def _modes() -> list[str]:
    return ["async", "sync"]


def _methods() -> list[str]:
    return list(BUILTIN_METHODS)


def _token_problem(value: Any) -> str | None:
    from dfrl.experiments.tokens import token_problem

    why = token_problem(value)
    return None if why is None else f"not a token: {why} (an integer >= 0 or a string " \
        "without white space; dfrl secret prints a strong one)"


ROBOT_RULES: dict[str, Rule] = {
    "id": Rule(str), "arena": Rule(str),
    "algo": Rule(str, choices=known_algorithms, what="algorithm"),
    "seed": Rule(int, nullable=True, low=0), "node": Rule(str, nullable=True),
}

JOIN_RULES: dict[str, Rule] = {"robot": Rule(dict), "after_round": Rule(int, low=1)}

_METHOD_HINT = "a new method is loaded into a running experiment with dfrl inject"
_FLAT_OUT = "null means flat out"

EXPERIMENT_RULES: dict[str, Rule] = {
    "name": Rule(str), "robots": Rule(list), "iterations": Rule(int, low=1),
    "respite": Rule(int, low=1), "seed": Rule(int, low=0),
    "mode": Rule(str, choices=_modes, what="mode"),
    "rtf": Rule(float, nullable=True, above=0, hint=_FLAT_OUT),
    "method": Rule(str, choices=_methods, what="method", hint=_METHOD_HINT),
    "methods": Rule(dict), "rest_s": Rule(float, nullable=True, low=0),
    "token": Rule(object, nullable=True, check=_token_problem), "trainer": Rule(dict),
    "joins": Rule(list),
    "timeout_s": Rule(float, above=0), "title": Rule(str), "console": Rule(str, nullable=True),
    "tolerate_lost_robots": Rule(int, low=0), "tolerate_missing_rounds": Rule(int, low=0),
    "tolerate_method_errors": Rule(int, low=0),
    "eval_every": Rule(int, low=0, hint="0 means no evaluation"), "eval_steps": Rule(int, low=1),
}

NODE_RULES: dict[str, Rule] = {
    "robot": Rule(str), "out_dir": Rule(str), "arena": Rule(str),
    "algo": Rule(str, choices=known_algorithms, what="algorithm"),
    "seed": Rule(int, low=0), "iterations": Rule(int, low=0), "respite": Rule(int, low=1),
    "mode": Rule(str, choices=_modes, what="mode"),
    "rtf": Rule(float, nullable=True, low=0, hint="null or 0 means flat out"),
    "token": Rule(object, nullable=True, check=_token_problem), "trainer": Rule(dict),
    "grace_s": Rule(float, low=0),
    "sync_timeout_s": Rule(float, above=0), "progress_every": Rule(int, low=0),
    "events": Rule(bool), "bench_table": Rule(list, nullable=True), "host": Rule(str),
    "tls": Rule(str, nullable=True),
    "eval_every": Rule(int, low=0, hint="0 means no evaluation"), "eval_steps": Rule(int, low=1),
}


def check_robot_id(path: str, rid: Any) -> list[str]:
    if isinstance(rid, str) and not _ROBOT_ID.match(rid):
        return [f"{path}: robot id {rid!r}: use a lower-case name like r1 "
                "(letters, digits, _)"]
    return []


def check_node_address(path: str, text: Any) -> list[str]:
    if not isinstance(text, str):
        return []
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        return [f"{path}: robot node {text!r}: use HOST:PORT, e.g. 10.0.0.7:7001"]
    return []


def check_arena(path: str, arena: Any, cache: dict[str, str | None]) -> list[str]:
    """The arena exists and parses (built-in name or file)."""
    if not isinstance(arena, str):
        return []
    if arena not in cache:
        from dfrl.arenas.spec import ArenaError, load_arena

        try:
            load_arena(arena)
            cache[arena] = None
        except (ArenaError, OSError, ValueError) as exc:
            cache[arena] = " ".join(str(exc).split())
    return [f"{path}: {cache[arena]}"] if cache[arena] else []


def check_trainer(path: str, trainer: Any) -> list[str]:
    """``trainer`` holds known :class:`dfrl.robots.training.TrainerConfig` fields of the right
    types, and the result builds."""
    if not isinstance(trainer, dict) or not trainer:
        return []
    from dfrl.robots.training import TrainerConfig

    defaults = TrainerConfig().to_dict()
    problems = _check_like(path, trainer, defaults)
    owned = {"arena", "algo", "seed", "iterations"} & set(trainer)
    problems += [f"{path}.{k}: set by the experiment (robots[..].{k} or {k}), not in trainer"
                 for k in sorted(owned)]
    if not problems:
        try:
            TrainerConfig.from_dict({**defaults, **trainer})
        except (TypeError, ValueError) as exc:
            problems.append(f"{path}: {exc}")
    return problems


def _check_like(path: str, data: dict[str, Any], model: dict[str, Any]) -> list[str]:
    """Keys and value kinds of ``data`` against the defaults ``model`` (nested)."""
    out = []
    for key, value in data.items():
        here = f"{path}.{key}"
        if key not in model:
            out.append(f"{here}: unknown key (known: {', '.join(sorted(model))})")
            continue
        ref = model[key]
        if isinstance(ref, dict):
            out += (_check_like(here, value, ref) if isinstance(value, dict)
                    else [f"{here}: expected an object, got {value!r}"])
        elif ref is not None:
            kind = float if isinstance(ref, float) else type(ref)
            out += check_value(here, value, Rule(kind))
    return out


def check_experiment(data: Any, resources: bool = True) -> list[str]:
    """Every problem of an experiment config in its JSON form (empty: it can run).

    Parameters
    ----------
    data : dict
        As read from the JSON file.
    resources : bool
        Also load every arena (a built-in name or a file that must parse).
    """
    out = check_keys("", data, EXPERIMENT_RULES, extra=COMMENT_KEYS)
    if not isinstance(data, dict):
        return out
    arenas: dict[str, str | None] = {}
    robots = data.get("robots", [])
    entries: list[tuple[str, dict[str, Any]]] = []
    if isinstance(robots, list):
        if not robots:
            out.append("robots: an experiment needs at least one robot")
        entries += [(f"robots[{i}]", r) for i, r in enumerate(robots)]
    for i, j in enumerate(data.get("joins", []) if isinstance(data.get("joins"), list) else []):
        out += check_keys(f"joins[{i}]", j, JOIN_RULES, required=("robot",))
        if isinstance(j, dict) and isinstance(j.get("robot"), dict):
            entries.append((f"joins[{i}].robot", j["robot"]))
    ids: dict[str, str] = {}
    nodes: dict[str, str] = {}
    for path, r in entries:
        out += check_keys(path, r, ROBOT_RULES, required=("id", "arena"))
        if not isinstance(r, dict):
            continue
        out += check_robot_id(f"{path}.id", r.get("id"))
        out += check_node_address(f"{path}.node", r.get("node"))
        if resources:
            out += check_arena(f"{path}.arena", r.get("arena"), arenas)
        rid, node = r.get("id"), r.get("node")
        if isinstance(rid, str):
            if rid in ids:
                out.append(f"{path}.id: robot id {rid!r} is already used by {ids[rid]}")
            ids.setdefault(rid, path)
        if isinstance(node, str):
            if node in nodes:
                out.append(f"{path}.node: {node} already runs {nodes[node]}; one robot per node")
            nodes.setdefault(node, path)
    methods = data.get("methods", {})
    if isinstance(methods, dict):
        algos = set(known_algorithms())
        for algo, method in methods.items():
            if algo not in algos:
                out.append(f"methods.{algo}: unknown algorithm {algo!r}; known: "
                           f"{', '.join(sorted(algos))}")
            out += check_value(f"methods.{algo}", method,
                               Rule(str, choices=_methods, what="method", hint=_METHOD_HINT))
    if "trainer" in data:
        out += check_trainer("trainer", data["trainer"])
    out += check_eval_every(data)
    return out


def check_eval_every(data: dict[str, Any]) -> list[str]:
    """An ``eval_every`` larger than the run's iterations would evaluate nothing, silently:
    it is a problem (0 is the way to say "no evaluation")."""
    every, iterations = data.get("eval_every"), data.get("iterations")
    if iterations is None:
        from dfrl.experiments.driver.config import ExperimentConfig

        iterations = ExperimentConfig.__dataclass_fields__["iterations"].default
    if (isinstance(every, int) and isinstance(iterations, int) and not isinstance(every, bool)
            and 0 < iterations < every):
        return [f"eval_every: {every} is more than the {iterations} iterations, so no "
                "evaluation would run (0 means no evaluation)"]
    return []


def check_node(data: Any) -> list[str]:
    """Every problem of a robot node config (:class:`dfrl.experiments.driver.config.RobotConfig`)."""
    out = check_keys("", data, NODE_RULES, required=("robot", "out_dir"))
    if not isinstance(data, dict):
        return out
    out += check_robot_id("robot", data.get("robot"))
    table = data.get("bench_table")
    if isinstance(table, list) and (len(table) != 2 or not all(
            isinstance(n, int) and not isinstance(n, bool) and n > 0 for n in table)):
        out.append(f"bench_table: expected [STATES, ACTIONS], two positive integers, got {table!r}")
    if "trainer" in data:
        out += check_trainer("trainer", data["trainer"])
    return out
