"""Config dataclasses <-> JSON-ready dicts, for :mod:`dfrl.experiments.driver.config`: a config's
dict form (enums as their values, tuples as lists) and building one back from a checked dict."""
from __future__ import annotations

import dataclasses
import json
from enum import Enum
from typing import Any

from dfrl.experiments.driver.config_check import ConfigError

__all__ = ["config_from_dict", "config_to_dict", "raw_fields"]


def config_to_dict(cfg: Any) -> dict[str, Any]:
    """A config dataclass with a ``mode`` enum as a JSON-ready dict (lists for tuples)."""
    d = json.loads(json.dumps(dataclasses.asdict(cfg), default=str))
    d["mode"] = cfg.mode.value
    return d


def config_from_dict(cls: type, data: dict[str, Any], problems: list[str]) -> Any:
    """Build config dataclass ``cls`` from ``data`` once ``problems`` (every problem of
    ``data``, see :mod:`dfrl.experiments.driver.config_check`) is empty.

    Raises
    ------
    ConfigError
        ``problems`` is not empty.
    """
    if problems:
        raise ConfigError(problems)
    names = {f.name for f in dataclasses.fields(cls)}
    return cls(**{k: v for k, v in data.items() if k in names})


def raw_fields(cfg: Any) -> dict[str, Any]:
    """The JSON form of a config dataclass as built (entries may still be dicts)."""
    raw = {f.name: getattr(cfg, f.name) for f in dataclasses.fields(cfg)}
    if isinstance(raw.get("mode"), Enum):
        raw["mode"] = raw["mode"].value
    return raw
