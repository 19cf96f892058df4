"""Checking an experiment config before anything starts: every problem at once, each with its
key path (the rules and the shared checks are in :mod:`dfrl.experiments.config_rules`).

:func:`check_experiment` takes the JSON form (a dict, as read from a file) and returns the
list of problems, each a line such as
``robots[1].algo: unknown algorithm 'ppo'; known: dqn, linear, qlearning, sarsa``. What is
checked: unknown keys and values (with the nearest known name), types (``"2000"`` is not an
integer, a bool is not a number), ranges, robot ids, ``HOST:PORT`` robot hosts, unique ids
and robot hosts, known algorithms and aggregation methods (and that a function learner's
method applies to parameter vectors), a grid federation's rules (:func:`check_federation`),
the ``trainer`` fields, and (``resources=True``) that every arena exists and parses
(:func:`dfrl.arenas.load_arena`, whose errors name file and place).
"""

from __future__ import annotations

from typing import Any

from dfrl.experiments.config_rules import (
    Rule,
    check_keys,
    check_robot_id,
    check_trainer,
    check_value,
    known_algorithms,
    token_rule,
    unknown_value,
)
from dfrl.experiments.suggestions import did_you_mean
from dfrl.experiments.robot_host.config import DEFAULT_ITERATIONS, modes

__all__ = [
    "BUILTIN_METHODS",
    "COMMENT_KEYS",
    "FEDERATIONS",
    "GRID",
    "ITINERARIES",
    "PARAMS_REFUSED",
    "check_experiment",
    "host_port_problem",
]

#: Aggregation methods built into the agent; others are injected into a running experiment
#: with ``dfrl inject`` (an experiment config can only name these).
BUILTIN_METHODS: tuple[str, ...] = ("average", "max", "visit_average")

#: The federation that puts every robot, whatever its learner, under one agent carrying Q-tables
#: on the discretised state grid (function learners show their Q-function there:
#: robots/grid_view.py).
GRID = "grid"

#: How the robots of an experiment are federated: ``per_algorithm`` (one agent per algorithm:
#: tables for the tabular learners, parameter vectors for the function learners) or ``grid``.
FEDERATIONS: tuple[str, ...] = ("per_algorithm", GRID)

#: How an agent goes over its robots each round: ``chain`` (one walk out and back, the default)
#: or ``tree`` (clones over a tree of fan-out ``fanout``, platform_pl/dfrl_agent/dfrl_tree.pl).
ITINERARIES: tuple[str, ...] = ("chain", "tree")

#: Keys a config file may carry that are not fields (notes for people).
COMMENT_KEYS = frozenset({"comment"})


def _methods() -> list[str]:
    return list(BUILTIN_METHODS)


ROBOT_RULES: dict[str, Rule] = {
    "id": Rule(str),
    "arena": Rule(str),
    "algo": Rule(str, choices=known_algorithms, what="algorithm"),
    "seed": Rule(int, nullable=True, low=0),
    "robot_host": Rule(str, nullable=True),
}

#: Keys of a robot entry that were renamed, and what to write instead.
ROBOT_RENAMED = {"node": "renamed robot_host (HOST:PORT of a dfrl robot service)"}

JOIN_RULES: dict[str, Rule] = {"robot": Rule(dict), "after_round": Rule(int, low=1)}

_METHOD = Rule(
    str,
    choices=_methods,
    what="method",
    hint="a new method is loaded into a running experiment with dfrl inject",
)

EXPERIMENT_RULES: dict[str, Rule] = {
    "name": Rule(str),
    "robots": Rule(list),
    "iterations": Rule(int, low=1),
    "respite": Rule(int, low=1),
    "seed": Rule(int, low=0),
    "mode": Rule(str, choices=modes, what="mode"),
    "rtf": Rule(float, nullable=True, above=0, hint="null means flat out"),
    "method": _METHOD,
    "methods": Rule(dict),
    "rest_s": Rule(float, nullable=True, low=0),
    "token": token_rule(),
    "trainer": Rule(dict),
    "joins": Rule(list),
    "timeout_s": Rule(float, above=0),
    "skip_after_s": Rule(float, above=0),
    "partition_wait_s": Rule(float, low=0, hint="0: no wait, robots not answering are lost"),
    "title": Rule(str),
    "console": Rule(str, nullable=True),
    "tolerate_lost_robots": Rule(int, low=0),
    "tolerate_missing_rounds": Rule(int, low=0),
    "tolerate_method_errors": Rule(int, low=0),
    "eval_every": Rule(int, low=0, hint="0 means no evaluation"),
    "eval_steps": Rule(int, low=1),
    "federation": Rule(str, choices=lambda: list(FEDERATIONS), what="federation"),
    "itinerary": Rule(str, choices=lambda: list(ITINERARIES), what="itinerary"),
    "fanout": Rule(int, low=2, hint="children of each stop in a tree itinerary"),
    "learners": Rule(dict, hint="plug-in learners: name -> 'module:Class' or 'file.py:Class'"),
}


def host_port_problem(text: str) -> str | None:
    """Why ``text`` is not ``HOST:PORT`` (a port 1..65535), or None."""
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        return f"robot host {text!r}: use HOST:PORT, e.g. 10.0.0.7:7001"
    return None


def check_arena(path: str, arena: Any, cache: dict[str, str | None]) -> list[str]:
    """The arena exists and parses (built-in name or file)."""
    if not isinstance(arena, str):
        return []
    if arena not in cache:
        from dfrl.arenas.spec import ArenaError, builtin_arena_names, load_arena

        try:
            load_arena(arena)
            cache[arena] = None
        except (ArenaError, OSError, ValueError) as exc:
            near = did_you_mean(arena, builtin_arena_names()) if "/" not in arena else ""
            cache[arena] = " ".join(str(exc).split()) + (f" ({near})" if near else "")
    return [f"{path}: {cache[arena]}"] if cache[arena] else []


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
    if isinstance(data.get("learners"), dict):  # before the robots name them
        from dfrl.robots.plugins import section_problems

        out += section_problems(data["learners"])
    # the learners this config may name: built in, installed, or in its own ``learners``
    # section (not one another config registered earlier in this process)
    algos = config_algorithms(data.get("learners"))
    robots = data.get("robots", [])
    entries: list[tuple[str, Any]] = []
    if isinstance(robots, list):
        if not robots:
            out.append("robots: an experiment needs at least one robot")
        entries += [(f"robots[{i}]", r) for i, r in enumerate(robots)]
    for i, j in enumerate(data.get("joins", []) if isinstance(data.get("joins"), list) else []):
        out += check_keys(f"joins[{i}]", j, JOIN_RULES, required=("robot",))
        if isinstance(j, dict) and isinstance(j.get("robot"), dict):
            entries.append((f"joins[{i}].robot", j["robot"]))
    out += check_robots(entries, resources, algos)
    if data.get("federation") == GRID:
        out += check_federation(data)
    else:
        out += check_params_methods(data, entries)
    methods = data.get("methods", {})
    if isinstance(methods, dict):
        for algo, method in methods.items():
            if algo not in algos:
                out.append(unknown_value(f"methods.{algo}", "algorithm", algo, algos))
            out += check_value(f"methods.{algo}", method, _METHOD)
    if "trainer" in data:
        out += check_trainer("trainer", data["trainer"])
    return out + check_eval_every(data)


def config_algorithms(section: Any) -> list[str]:
    """The learners a config may name: the built-in ones, the installed plug-ins and those of
    its own ``learners`` section (``section``, registered by :func:`check_experiment` first)."""
    from dfrl.robots.learners import LEARNERS
    from dfrl.robots.plugins import installed

    own = [str(name) for name in section] if isinstance(section, dict) else []
    return sorted({*LEARNERS, *installed(), *own})


def check_robots(
    entries: list[tuple[str, Any]], resources: bool, algos: list[str] | None = None
) -> list[str]:
    """Problems of robot entries ``(key path, JSON form)``: each one's keys, id, robot host
    and (``resources``) arena; ids and robot hosts unique across all of them. ``algos``: the
    learners they may name (default: every learner known in this process, as for a robot that
    joins a running experiment, whose config registered its plug-ins)."""
    rules = ROBOT_RULES
    if algos is not None:
        names = list(algos)
        rules = {**ROBOT_RULES, "algo": Rule(str, choices=lambda: names, what="algorithm")}
    out: list[str] = []
    arenas: dict[str, str | None] = {}
    ids: dict[str, str] = {}
    hosts: dict[str, str] = {}
    for path, r in entries:
        out += check_keys(path, r, rules, required=("id", "arena"), renamed=ROBOT_RENAMED)
        if not isinstance(r, dict):
            continue
        rid, host = r.get("id"), r.get("robot_host")
        out += check_robot_id(f"{path}.id", rid)
        if isinstance(host, str) and host_port_problem(host):
            out.append(f"{path}.robot_host: {host_port_problem(host)}")
        if resources:
            out += check_arena(f"{path}.arena", r.get("arena"), arenas)
        if isinstance(rid, str):
            if rid in ids:
                out.append(f"{path}.id: robot id {rid!r} is already used by {ids[rid]}")
            ids.setdefault(rid, path)
        if isinstance(host, str):
            if host in hosts:
                out.append(
                    f"{path}.robot_host: {host} already runs {hosts[host]}; one robot "
                    "per robot host"
                )
            hosts.setdefault(host, path)
    return out


#: Why a built-in method does not apply to parameter vectors (an agent of function learners,
#: ``linear`` or ``dqn``, carries them); the agent refuses them likewise
#: (``domain_error(params_method, M)``, ``platform_pl/dfrl_agent/dfrl_aggregation.pl``).
PARAMS_REFUSED: dict[str, str] = {
    "max": "the element-wise maximum of the weights of different networks is no network",
    "visit_average": "parameters have no visit counts",
}


def check_params_methods(data: dict[str, Any], entries: list[tuple[str, Any]]) -> list[str]:
    """The method of every function learner's algorithm among ``entries`` (robots and joins)
    applies to parameter vectors: ``average`` (FedAvg) does, ``max`` and ``visit_average``
    do not."""
    from dfrl.robots.learners import is_tabular

    given = data.get("methods")
    methods: dict[str, Any] = given if isinstance(given, dict) else {}
    algos = [r.get("algo", "qlearning") for _, r in entries if isinstance(r, dict)]
    algos = list(dict.fromkeys(a for a in algos if isinstance(a, str) and a in known_algorithms()))
    tabular = any(is_tabular(a) for a in algos)
    out: list[str] = []
    for algo in algos:
        if is_tabular(algo):
            continue
        path = f"methods.{algo}" if algo in methods else "method"
        method = methods.get(algo, data.get("method", "average"))
        if not isinstance(method, str) or method not in PARAMS_REFUSED:
            continue
        also = (
            f' (methods: {{"{algo}": "average"}} keeps {method} for the tabular robots)'
            if path == "method" and tabular
            else ""
        )
        out.append(
            f"{path}: {method} does not apply to the {algo} robots: {algo} is a function "
            f"learner, its agent carries parameter vectors, and "
            f"{PARAMS_REFUSED[method]}; methods that do: average (FedAvg){also}"
        )
    return out


def check_federation(data: dict[str, Any]) -> list[str]:
    """A grid federation (``"federation": "grid"``): robots of any learners, tabular and
    function, share Q-tables on the state grid under one agent, so every built-in method
    applies; what cannot work with one agent is refused: per-algorithm ``methods`` (the agent
    has one method, ``method``) and ``joins`` (a joiner is handed to the agent of its
    algorithm)."""
    out: list[str] = []
    methods = data.get("methods")
    if isinstance(methods, dict) and methods:
        out.append(
            f"methods: a grid federation has one agent for all its robots, so one method: "
            f'give it in "method" instead of per algorithm ({", ".join(methods)})'
        )
    joins = data.get("joins")
    if isinstance(joins, list) and joins:
        out.append(
            "joins: a robot cannot join a grid federation (a joiner is handed to the "
            "agent of its algorithm); list it in robots"
        )
    listed = data.get("robots")
    robots: list[Any] = listed if isinstance(listed, list) else []
    for i, robot in enumerate(robots):
        algo = robot.get("algo") if isinstance(robot, dict) else None
        if isinstance(algo, str) and algo in known_algorithms() and not _distillable(algo):
            out.append(
                f"robots[{i}].algo: {algo} has no q_model(), so its Q-function cannot be "
                "read on the grid nor distilled back: it cannot join a grid federation "
                "(robots/README.md, 'Bring your own learner')"
            )
    return out


def _distillable(algo: str) -> bool:
    from dfrl.robots.approx import FunctionLearner
    from dfrl.robots.learners import learner_class

    cls = learner_class(algo)
    return not issubclass(cls, FunctionLearner) or cls.q_model is not FunctionLearner.q_model


def check_eval_every(data: dict[str, Any]) -> list[str]:
    """An ``eval_every`` larger than the run's iterations would evaluate nothing, silently:
    it is a problem (0 is the way to say "no evaluation")."""
    every, iterations = data.get("eval_every"), data.get("iterations", DEFAULT_ITERATIONS)
    if (
        isinstance(every, int)
        and isinstance(iterations, int)
        and not isinstance(every, bool)
        and 0 < iterations < every
    ):
        return [
            f"eval_every: {every} is more than the {iterations} iterations, so no "
            "evaluation would run (0 means no evaluation)"
        ]
    return []
