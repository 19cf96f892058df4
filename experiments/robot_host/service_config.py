"""The ``configure`` request of a ``dfrl robot`` service (:mod:`.service`): its JSON checked
and turned into the robot's :class:`~dfrl.experiments.robot_host.config.RobotConfig`."""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from pathlib import Path

from dfrl.arenas import ArenaError, builtin_arena_names, parse_arena
from dfrl.experiments.robot_host.config import RobotConfig
from dfrl.experiments.suggestions import did_you_mean
from dfrl.experiments.tokens import Token
from dfrl.pybridge.serving import RequestError
from dfrl.pybridge.terms import Term

_EXPERIMENT_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,127}")
_ARENA_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,63}")
#: The service's own arena files: ``WORKDIR/arenas/NAME.json``, regular files of at most this size.
ARENA_FOLDER = "arenas"
MAX_ARENA_BYTES = 1 << 20


def config_error(message: str) -> RequestError:
    """The error a bad ``configure`` request gets: ``robot_config_error(Message)``."""
    return RequestError(Term("robot_config_error", message))


def parse_configure(
    text: str, tokens: Sequence[Token], workdir: Path
) -> tuple[str, RobotConfig, bool]:
    """A ``configure`` request's JSON text checked: ``(experiment, its RobotConfig, resume)``;
    the arena it carries and the text itself are kept in ``WORKDIR/EXPERIMENT/service/``.

    Raises
    ------
    RequestError
        ``robot_config_error(Why)``: not JSON, a bad experiment name, a bad robot
        config, a token other than the service's.
    """
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise config_error(f"not JSON: {exc}") from None
    if not isinstance(data, dict):
        raise config_error("the configuration is a JSON object")
    experiment = data.get("experiment")
    if (
        not isinstance(experiment, str)
        or not _EXPERIMENT_ID.fullmatch(experiment)
        or set(experiment) == {"."}
    ):
        raise config_error(
            f"experiment {experiment!r}: a name of letters, digits, '.', '_' and '-'"
        )
    node = data.get("robot")
    if not isinstance(node, dict):
        raise config_error("'robot' must be a JSON object (a robot process config)")
    node = dict(node)
    resume = bool(node.pop("resume", data.get("resume", False)))
    node.pop("out_dir", None)
    # a driver sends no token (the peer proved one); an older one did: it must match
    if "token" in node and str(node["token"]) not in {str(t) for t in tokens}:
        raise config_error("the experiment's token differs from this robot's token")
    node.pop("token", None)
    if node.get("learners"):
        # a spec would make this host import a module or file a token holder names: code its
        # owner did not choose. The owner installs a learner here (an entry point) instead.
        raise config_error(
            f"learners {sorted(node['learners'])}: a robot host loads no learner a driver names; "
            "install it on this host as a dfrl.learners entry point (robots/README.md, 'Bring "
            "your own learner') and the robot can name it in algo"
        )
    out = workdir / experiment
    arena = data.get("arena")
    if arena is not None:
        path = out / "service" / "arena.json"
        text_arena = _arena_object_text(arena, str(node.get("arena", "arena")))
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text_arena, encoding="utf-8")
        node["arena"] = str(path)
    else:
        node["arena"] = service_arena(node.get("arena", "r4"), workdir)
    try:
        config = RobotConfig.from_dict(dict(node, out_dir=str(out)))
    except (TypeError, ValueError) as exc:
        raise config_error(str(exc)) from None
    (out / "service").mkdir(parents=True, exist_ok=True)
    (out / "service" / "configure.json").write_text(text, encoding="utf-8")
    return experiment, config, resume


def service_arena(name: object, workdir: Path) -> str:
    """What the robot process loads for the arena ``name`` a peer asked for: a built-in
    arena's name, or the path of ``WORKDIR/arenas/NAME.json``, a regular file of at most
    :data:`MAX_ARENA_BYTES` inside that folder (a symbolic link out of it does not count).

    A peer holds the token, not the host: nothing else on the host may be read as an arena,
    and the refusal is one message, whatever the name (a path, ``../``, a device, a missing
    or unreadable file): it lists the names this service offers and says nothing of files.

    Raises
    ------
    RequestError
        ``robot_config_error(Why)`` for any name that is not one of those.
    """
    builtin = builtin_arena_names()
    own = _own_arenas(workdir)
    if isinstance(name, str) and _ARENA_NAME.fullmatch(name):
        if name.lower() in builtin:
            return name.lower()
        if name in own:
            return str(own[name])
    offered = [*builtin, *sorted(own)]
    near = did_you_mean(name, offered) if isinstance(name, str) and len(name) <= 64 else ""
    raise config_error(
        f"unknown arena {str(name)[:64]!r}{f' ({near})' if near else ''}: this "
        f"robot host offers the arenas {', '.join(offered)} (its built-in "
        f"arenas and the files of its {ARENA_FOLDER}/ folder); a driver sends "
        "any other arena as its JSON object"
    )


def _own_arenas(workdir: Path) -> dict[str, Path]:
    """The service's own arena files by name: regular ``*.json`` files of bounded size
    directly in ``WORKDIR/arenas/`` (their resolved paths inside it)."""
    folder = workdir / ARENA_FOLDER
    try:
        root = folder.resolve(strict=True)
        entries = list(root.iterdir())
    except OSError:
        return {}
    found: dict[str, Path] = {}
    for entry in entries[:1000]:
        if entry.suffix != ".json" or not _ARENA_NAME.fullmatch(entry.stem):
            continue
        try:
            real = entry.resolve(strict=True)
            st = real.stat()
        except OSError:
            continue
        if real.parent == root and real.is_file() and st.st_size <= MAX_ARENA_BYTES:
            found[entry.stem] = real
    return found


def _arena_object_text(arena: object, name: str) -> str:
    """The arena object a driver sent, checked (an arena of the documented format, at most
    :data:`MAX_ARENA_BYTES` as JSON), as the text to keep.

    Raises
    ------
    RequestError
        ``robot_config_error(Why)``: not an object, too large, or not a valid arena.
    """
    if not isinstance(arena, dict):
        raise config_error("'arena' must be an arena's JSON object or null")
    text = json.dumps(arena)
    if len(text) > MAX_ARENA_BYTES:
        raise config_error(
            f"the arena object is {len(text)} bytes of JSON; at most {MAX_ARENA_BYTES}"
        )
    try:
        parse_arena(arena, f"the arena object of {name[:64]!r}")
    except ArenaError as exc:
        raise config_error(str(exc)) from None
    return text
