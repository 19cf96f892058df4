"""The ``configure`` request of a ``dfrl robot`` service (:mod:`.service`): its JSON checked
and turned into the robot's :class:`~dfrl.experiments.robot_host.config.RobotConfig`."""
from __future__ import annotations

import json
import re
from collections.abc import Sequence
from pathlib import Path

from dfrl.experiments.robot_host.config import RobotConfig
from dfrl.experiments.tokens import Token
from dfrl.pybridge.serving import RequestError
from dfrl.pybridge.terms import Term

_EXPERIMENT_ID = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]{0,127}")


def config_error(message: str) -> RequestError:
    """The error a bad ``configure`` request gets: ``robot_config_error(Message)``."""
    return RequestError(Term("robot_config_error", message))


def parse_configure(text: str, tokens: Sequence[Token], workdir: Path
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
    if not isinstance(experiment, str) or not _EXPERIMENT_ID.fullmatch(experiment) \
            or set(experiment) == {"."}:
        raise config_error(f"experiment {experiment!r}: a name of letters, digits, "
                            "'.', '_' and '-'")
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
    out = workdir / experiment
    arena = data.get("arena")
    if arena is not None:
        if not isinstance(arena, dict):
            raise config_error("'arena' must be an arena's JSON object or null")
        path = out / "service" / "arena.json"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(arena), encoding="utf-8")
        node["arena"] = str(path)
    try:
        config = RobotConfig.from_dict(dict(node, out_dir=str(out)))
    except (TypeError, ValueError) as exc:
        raise config_error(str(exc)) from None
    (out / "service").mkdir(parents=True, exist_ok=True)
    (out / "service" / "configure.json").write_text(text, encoding="utf-8")
    return experiment, config, resume
