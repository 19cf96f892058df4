"""Learners from outside the package: found by name, loaded from a module or a file.

A plug-in learner is a class that subclasses :class:`dfrl.robots.approx.FunctionLearner` (the
interface the built-in ``linear`` and ``dqn`` implement, and that the tabular learners mirror:
``act``, ``learn``, ``get_params``/``set_params``, ``describe``; robots/README.md, "Bring your
own learner"). A name resolves, in this order, to

1. a built-in learner (:data:`dfrl.robots.learners.LEARNERS`);
2. a learner registered in this process (:func:`register_learner`, e.g. by a config's
   ``"learners"`` section: ``{"name": "module:Class"}`` or ``{"name": "path/to/file.py:Class"}``);
3. an entry point of the group ``dfrl.learners`` of an installed distribution
   (``[project.entry-points."dfrl.learners"] name = "module:Class"``).

A spec ``module:Class`` imports ``module``; ``file.py:Class`` loads that file (an absolute
path: a config's relative paths are resolved against its folder when it is read).
"""

from __future__ import annotations

import functools
import importlib
import importlib.util
import sys
from importlib.metadata import entry_points
from pathlib import Path
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from dfrl.robots.approx import FunctionLearner

#: The entry-point group installed distributions declare their learners in.
GROUP: str = "dfrl.learners"


@dataclass(frozen=True)
class Plugin:
    """A plug-in learner registered in this process."""

    name: str
    spec: str
    options: dict[str, Any]
    cls: type["FunctionLearner"]


#: Learners registered in this process, by name.
_REGISTERED: dict[str, Plugin] = {}


class PluginError(ValueError):
    """A plug-in learner that cannot be loaded or is not a learner (the message says why)."""


def _check_name(name: str) -> None:
    if (
        not name
        or not name.replace("_", "a").isalnum()
        or not name[0].isalpha()
        or name != name.lower()
    ):
        raise PluginError(
            f"learner name {name!r}: lower-case letters, digits and '_', "
            "starting with a letter (it names agents and result columns)"
        )


def load_class(spec: str) -> type["FunctionLearner"]:
    """The class a spec ``module:Class`` or ``path/file.py:Class`` names, checked to be a
    :class:`~dfrl.robots.approx.FunctionLearner`.

    Raises
    ------
    PluginError
        Malformed spec, module or file not found or failing to import, no such class, or a
        class that is not a learner.
    """
    from dfrl.robots.approx import FunctionLearner

    where, sep, attr = spec.rpartition(":")
    if not sep or not where or not attr.isidentifier():
        raise PluginError(f"learner spec {spec!r}: expected 'module:Class' or 'file.py:Class'")
    try:
        if where.endswith(".py"):
            module = _load_file(Path(where))
        else:
            module = importlib.import_module(where)
    except PluginError:
        raise
    except Exception as e:  # the user's module failing to import: say which and why
        raise PluginError(
            f"learner spec {spec!r}: importing {where} failed: {type(e).__name__}: {e}"
        ) from e
    cls = getattr(module, attr, None)
    if cls is None:
        raise PluginError(f"learner spec {spec!r}: {where} has no {attr}")
    if not (isinstance(cls, type) and issubclass(cls, FunctionLearner)):
        raise PluginError(
            f"learner spec {spec!r}: {attr} is not a subclass of "
            "dfrl.robots.approx.FunctionLearner (robots/README.md, "
            "'Bring your own learner')"
        )
    return cls


def _load_file(path: Path):  # noqa: ANN202 - a module
    if not path.is_absolute():
        raise PluginError(
            f"learner file {path}: the path must be absolute here (a config "
            "resolves it against its own folder)"
        )
    if not path.is_file():
        raise PluginError(f"learner file {path} does not exist")
    name = "dfrl_plugin_" + "".join(c if c.isalnum() else "_" for c in str(path))
    if name in sys.modules:
        return sys.modules[name]
    loader_spec = importlib.util.spec_from_file_location(name, path)
    if loader_spec is None or loader_spec.loader is None:
        raise PluginError(f"learner file {path} cannot be loaded as a module")
    module = importlib.util.module_from_spec(loader_spec)
    sys.modules[name] = module
    try:
        loader_spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    return module


def register_learner(
    name: str, spec: str, options: dict[str, Any] | None = None
) -> type["FunctionLearner"]:
    """Load the learner ``spec`` names and register it as ``name`` in this process, with the
    keyword ``options`` its constructor gets after ``(obs_dim, n_actions, params, rng)``.
    Again with the same spec and options nothing changes; with others they replace the
    earlier ones (a process that runs one experiment after another, e.g. a ``dfrl robot``
    service, takes each run's own).

    Raises
    ------
    PluginError
        A bad name or spec (see :func:`load_class`), or a built-in's name.
    """
    from dfrl.robots.learners import LEARNERS

    _check_name(name)
    opts = dict(options or {})
    if name in LEARNERS:
        raise PluginError(f"learner name {name!r} is a built-in learner's; pick another")
    known = _REGISTERED.get(name)
    if known is not None and (known.spec, known.options) == (spec, opts):
        return known.cls
    cls = load_class(spec)
    cls.name = name
    _REGISTERED[name] = Plugin(name, spec, opts, cls)
    return cls


def options(name: str) -> dict[str, Any]:
    """The constructor options of the plug-in ``name`` ({} for any other learner)."""
    known = _REGISTERED.get(name)
    return dict(known.options) if known is not None else {}


@functools.lru_cache(maxsize=1)
def _installed() -> tuple[tuple[str, str], ...]:
    return tuple((ep.name, ep.value) for ep in entry_points(group=GROUP))


def installed() -> dict[str, str]:
    """Name -> ``module:Class`` of every entry point of :data:`GROUP` (read once a process:
    scanning the installed distributions costs ~10 ms, and config checks ask often)."""
    return dict(_installed())


def find(name: str) -> type["FunctionLearner"] | None:
    """The plug-in learner called ``name`` (registered, else installed), or None.

    Raises
    ------
    PluginError
        An installed entry point of that name that does not load.
    """
    known = _REGISTERED.get(name)
    if known is not None:
        return known.cls
    spec = installed().get(name)
    return register_learner(name, spec) if spec is not None else None


def plugin_names() -> list[str]:
    """Names of the plug-in learners known here (registered and installed)."""
    return sorted({*_REGISTERED, *installed()})


def section_problems(section: Any) -> list[str]:
    """Register the learners of a config's ``learners`` section (``name -> "module:Class" |
    "file.py:Class" | {"class": ..., "options": {...}}``, a file's path absolute: see
    :func:`absolute_section`); every problem, located (``learners.NAME: ...``)."""
    if not isinstance(section, dict):
        return [
            "learners: expected an object of name -> 'module:Class' or "
            '{"class": ..., "options": {...}}'
        ]
    problems: list[str] = []
    for name, entry in section.items():
        try:
            spec, opts = _entry(entry)
            register_learner(str(name), spec, opts)
        except PluginError as e:
            problems.append(f"learners.{name}: {e}")
    return problems


def _entry(entry: Any) -> tuple[str, dict[str, Any]]:
    if isinstance(entry, str):
        return entry, {}
    if (
        isinstance(entry, dict)
        and isinstance(entry.get("class"), str)
        and isinstance(entry.get("options", {}), dict)
        and not set(entry) - {"class", "options"}
    ):
        return entry["class"], dict(entry.get("options", {}))
    raise PluginError(
        "expected 'module:Class', 'file.py:Class' or {\"class\": ..., \"options\": {...}}"
    )


def _absolute(spec: str, base: Path) -> str:
    where, sep, attr = spec.rpartition(":")
    if sep and where.endswith(".py") and not Path(where).is_absolute():
        return f"{(base / where).resolve()}:{attr}"
    return spec


def absolute_section(section: Any, base: Path) -> Any:
    """A config's ``learners`` section with every relative file path resolved against
    ``base`` (the config's folder); anything malformed is left for the check to report."""
    if not isinstance(section, dict):
        return section
    out: dict[Any, Any] = {}
    for name, entry in section.items():
        if isinstance(entry, str):
            out[name] = _absolute(entry, base)
        elif isinstance(entry, dict) and isinstance(entry.get("class"), str):
            out[name] = {**entry, "class": _absolute(entry["class"], base)}
        else:
            out[name] = entry
    return out
