"""What a config key may hold, and the checks every config shares (experiment and robot
process): one problem per line with its key path, every problem of a config at once.

A config is a frozen dataclass and its JSON form (:func:`json_form`); a checker takes the JSON
form (a dict, as read from a file) and returns its problems, each a line such as
``robots[1].algo: unknown algorithm 'dqn'; known: qlearning, sarsa``; :class:`ConfigError`
carries such a list. :func:`check_keys` checks an object against a table of :class:`Rule`:
unknown keys and values (with a "did you mean": :mod:`dfrl.experiments.suggestions`), renamed
keys, missing keys, types (``"2000"`` is not an integer, a bool is not a number), ranges and
known values.

A config is checked once, where it is parsed: ``from_dict`` checks the JSON form as a whole,
then builds the dataclass with ``_checked=True`` (a keyword-only init-only field), which tells
its ``__post_init__`` -- the check of a config built in Python -- that the whole was checked,
for it and for the entries it builds; a config built in Python without it checks itself.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from enum import Enum
from typing import Any

from dfrl.experiments.suggestions import did_you_mean

__all__ = [
    "ConfigError",
    "Rule",
    "TRAINER_OWNED",
    "check_keys",
    "check_robot_id",
    "check_trainer",
    "check_value",
    "json_form",
    "known_algorithms",
    "raise_problems",
    "resolve_trainer",
    "to_json_dict",
    "token_rule",
    "unknown_value",
]

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


def raise_problems(problems: Sequence[str]) -> None:
    """Raise :class:`ConfigError` with ``problems`` unless there are none."""
    if problems:
        raise ConfigError(problems)


def json_form(value: Any) -> Any:
    """A config (or any value inside one) in its JSON form: dataclasses as dicts, enums as
    their values, tuples as lists; other values as they are."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {f.name: json_form(getattr(value, f.name)) for f in dataclasses.fields(value)}
    if isinstance(value, Enum):
        return value.value
    if isinstance(value, (list, tuple)):
        return [json_form(v) for v in value]
    if isinstance(value, dict):
        return {k: json_form(v) for k, v in value.items()}
    return value


def to_json_dict(cfg: Any) -> dict[str, Any]:
    """:func:`json_form` of ``cfg``, whatever JSON cannot hold written as text."""
    return json.loads(json.dumps(json_form(cfg), default=str))


class JsonDicts:
    """The two dict forms of a config dataclass with a ``token`` field (a mixin)."""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the token included: :meth:`public_dict` for files)."""
        return to_json_dict(self)

    def public_dict(self) -> dict[str, Any]:
        """:meth:`to_dict` without the token: what a results file or a peer may see."""
        data = self.to_dict()
        data.pop("token", None)
        return data


# -- rules -------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Rule:
    """What one key may hold: ``kind`` (``int``, ``float``, ``str``, ``bool``, ``dict``,
    ``list``), ``None`` allowed when ``nullable``, a lower bound ``low`` (``above``: strictly
    greater), ``choices`` (a function returning the known values) named ``what``;
    ``check`` (a function returning a problem or None) replaces the kind and bounds (a value of
    more than one kind, such as a token)."""

    kind: type
    nullable: bool = False
    low: float | None = None
    above: float | None = None
    choices: Callable[[], Sequence[str]] | None = None
    what: str = "value"
    hint: str = ""
    check: Callable[[Any], str | None] | None = None


_TYPE_NAMES = {
    bool: "a boolean",
    int: "an integer",
    float: "a number",
    str: "a string",
    list: "a list",
    dict: "an object",
    type(None): "null",
}
_EXPECT = {
    int: "an integer",
    float: "a number",
    str: "a string",
    bool: "true or false",
    dict: "an object",
    list: "a list",
}


def _type_name(value: Any) -> str:
    return _TYPE_NAMES.get(type(value), type(value).__name__)


def _is_kind(value: Any, kind: type) -> bool:
    if kind is bool:
        return isinstance(value, bool)
    if isinstance(value, bool):
        return False
    return isinstance(value, (int, float)) if kind is float else isinstance(value, kind)


def check_value(path: str, value: Any, rule: Rule) -> list[str]:
    """Problems of ``value`` at ``path`` against ``rule`` (empty: fine)."""
    if value is None:
        return [] if rule.nullable else [f"{path}: must not be null"]
    if rule.check is not None:
        why = rule.check(value)
        return [] if why is None else [f"{path}: {why}"]
    if not _is_kind(value, rule.kind):
        return [
            f"{path}: expected {_EXPECT[rule.kind]}{' or null' if rule.nullable else ''}, "
            f"got {value!r} ({_type_name(value)})"
        ]
    if rule.kind is float and not math.isfinite(value):
        return [f"{path}: must be a finite number, got {value!r}"]
    hint = f" ({rule.hint})" if rule.hint else ""
    if rule.low is not None and value < rule.low:
        return [f"{path}: must be >= {rule.low:g}, got {value!r}{hint}"]
    if rule.above is not None and value <= rule.above:
        return [f"{path}: must be > {rule.above:g}, got {value!r}{hint}"]
    if rule.choices is not None:
        known = list(rule.choices())
        if value not in known:
            return [unknown_value(path, rule.what, value, known) + hint]
    return []


def unknown_value(path: str, what: str, value: Any, known: Sequence[str]) -> str:
    """The problem of a ``value`` at ``path`` that is none of the ``known`` names, with the
    nearest of them when one is near (:func:`dfrl.experiments.suggestions.did_you_mean`):
    ``robots[0].algo: unknown algorithm 'qlearing' (did you mean 'qlearning'?); known: ...``."""
    near = did_you_mean(value, known)
    return (
        f"{path}: unknown {what} {value!r}{f' ({near})' if near else ''}; known: {', '.join(known)}"
    )


def check_keys(
    path: str,
    data: Any,
    rules: Mapping[str, Rule],
    required: Sequence[str] = (),
    extra: frozenset[str] = frozenset(),
    renamed: Mapping[str, str] = {},
) -> list[str]:
    """Problems of object ``data``: not an object, unknown, renamed (``renamed`` maps an old
    key to its note, e.g. ``"renamed robot_host (...)"``) or missing keys, bad values; keys in
    ``extra`` are allowed and not checked."""
    if not isinstance(data, dict):
        return [f"{path or 'config'}: expected an object, got {data!r} ({_type_name(data)})"]
    out = []
    dot = f"{path}." if path else ""
    for key in data:
        if key in renamed:
            out.append(f"{dot}{key}: {renamed[key]}")
        elif key not in rules and key not in extra:
            near = did_you_mean(key, rules)
            also = f"; {near}" if near else ""
            out.append(f"{dot}{key}: unknown key{also} (known: {', '.join(sorted(rules))})")
    out += [f"{dot}{key}: missing (required)" for key in required if key not in data]
    for key, rule in rules.items():
        if key in data:
            out += check_value(f"{dot}{key}", data[key], rule)
    return out


# -- rules both configs share ------------------------------------------------------------------
def known_algorithms() -> list[str]:
    """The built-in learners and the plug-ins known in this process (registered by a config's
    ``learners`` section, or installed: dfrl.robots.plugins)."""
    from dfrl.robots.learners import LEARNERS
    from dfrl.robots.plugins import plugin_names

    return sorted({*LEARNERS, *plugin_names()})


def _token_problem(value: Any) -> str | None:
    from dfrl.experiments.tokens import token_problem

    why = token_problem(value)
    return (
        None
        if why is None
        else f"not a token: {why} (an integer >= 0 or a string "
        "without white space; dfrl secret prints a strong one)"
    )


def token_rule() -> Rule:
    """A platform token or null."""
    return Rule(object, nullable=True, check=_token_problem)


def check_robot_id(path: str, rid: Any) -> list[str]:
    if isinstance(rid, str) and not _ROBOT_ID.match(rid):
        return [f"{path}: robot id {rid!r}: use a lower-case name like r1 (letters, digits, _)"]
    return []


#: :class:`dfrl.robots.training.TrainerConfig` fields a ``trainer`` dict may not hold: the
#: experiment (or the robot process's config) sets them.
TRAINER_OWNED: frozenset[str] = frozenset({"arena", "algo", "seed", "iterations"})


def resolve_trainer(trainer: dict[str, Any]) -> dict[str, Any]:
    """``trainer`` (checked by :func:`check_trainer`) with every other
    :class:`~dfrl.robots.training.TrainerConfig` field at its default, nested fields included
    (the learner's ``alpha``, ``gamma``, ``epsilon`` schedule ...), as the robots build it
    (their defaults, updated with ``trainer``), without :data:`TRAINER_OWNED`: the same
    robots, and :func:`check_trainer` accepts it."""
    from dfrl.robots.training import TrainerConfig

    base = TrainerConfig().to_dict()
    base.update(trainer)
    full = TrainerConfig.from_dict(base).to_dict(full=True)
    return {k: v for k, v in full.items() if k not in TRAINER_OWNED}


def check_trainer(path: str, trainer: Any) -> list[str]:
    """``trainer`` holds known :class:`dfrl.robots.training.TrainerConfig` fields of the right
    types, and the result builds."""
    if not isinstance(trainer, dict) or not trainer:
        return []
    from dfrl.robots.training import TrainerConfig

    defaults = TrainerConfig().to_dict(full=True)
    problems = _check_like(path, trainer, defaults, trainer_choices())
    owned = TRAINER_OWNED & set(trainer)
    problems += [
        f"{path}.{k}: set by the experiment (robots[..].{k} or {k}), not in trainer"
        for k in sorted(owned)
    ]
    if not problems:
        try:
            TrainerConfig.from_dict({**defaults, **trainer})
        except (TypeError, ValueError) as exc:
            problems.append(f"{path}: {exc}")
    return problems


def trainer_choices() -> dict[str, list[str]]:
    """The known values of every enumerated ``trainer`` field, by its dotted key
    (``collision_response``, ``learner.epsilon.kind``, ``reward_shuffle_mode``, ...): the
    fields whose default is an :class:`~enum.Enum`, read from
    :class:`dfrl.robots.training.TrainerConfig` itself."""
    from dfrl.robots.reward_shuffle import ShuffleMode
    from dfrl.robots.training import TrainerConfig

    out = {"reward_shuffle_mode": [m.value for m in ShuffleMode]}

    def walk(obj: Any, prefix: str) -> None:
        for f in dataclasses.fields(obj):
            value = getattr(obj, f.name)
            if isinstance(value, Enum):
                out[prefix + f.name] = [str(m.value) for m in type(value)]
            elif dataclasses.is_dataclass(value):
                walk(value, f"{prefix}{f.name}.")

    walk(TrainerConfig(), "")
    return out


def _known(values: Sequence[str] | None) -> Callable[[], Sequence[str]] | None:
    """A :class:`Rule`'s ``choices`` that always answers ``values`` (None: no choices)."""
    if values is None:
        return None
    return lambda: values


def _check_like(
    path: str,
    data: dict[str, Any],
    model: dict[str, Any],
    choices: Mapping[str, Sequence[str]],
    rel: str = "",
) -> list[str]:
    """Keys and value kinds of ``data`` against the defaults ``model`` (nested), and the
    values of enumerated fields against ``choices`` (by key relative to the top, ``rel``)."""
    out = []
    for key, value in data.items():
        here = f"{path}.{key}"
        if key not in model:
            near = did_you_mean(key, model)
            out.append(
                f"{here}: unknown key{'; ' + near if near else ''} "
                f"(known: {', '.join(sorted(model))})"
            )
            continue
        ref = model[key]
        if isinstance(ref, dict):
            out += (
                _check_like(here, value, ref, choices, f"{rel}{key}.")
                if isinstance(value, dict)
                else [f"{here}: expected an object, got {value!r}"]
            )
        elif ref is not None:
            kind = float if isinstance(ref, float) else type(ref)
            known = choices.get(f"{rel}{key}")
            out += check_value(here, value, Rule(kind, choices=_known(known)))
    return out
