"""dfrl: decentralized federated reinforcement learning with mobile agents.

The package's subpackages mirror the project's folders:

==========================  ==================================================================
``dfrl.platform_pl``        the SWI-Prolog agent platform (Prolog sources and their location)
``dfrl.pybridge``           a Python process as a platform node (PySwip)
``dfrl.robots``             the pybullet e-puck, its Gymnasium env, Q-learning and SARSA
``dfrl.arenas``             arena files and their loader
``dfrl.experiments``        configuring, launching and reporting federated experiments
==========================  ==================================================================

The main Python API is re-exported here, imported on first use so that ``import dfrl`` stays
cheap: :class:`TrainerConfig`, :func:`train`, :func:`load_arena`, :class:`ExperimentConfig`,
:func:`run_experiment`. Importing ``dfrl`` registers the Gymnasium id ``dfrl/EPuck-v0``
(see :mod:`dfrl.robots.registration`).
"""

from __future__ import annotations

import importlib
import re
from pathlib import Path
from typing import Any

# In a source checkout the subpackages are the folders beside this one (pyproject.toml maps
# them, e.g. ``dfrl.robots`` -> ``robots/``); an installed wheel has them inside this folder.
# Extending __path__ makes both layouts import the same files, including when the checkout's
# root is on sys.path (``python -m`` from the root, pytest) and shadows the installed mapping.
_here = Path(__file__).resolve().parent
_checkout = not (_here / "robots").is_dir() and (_here.parent / "pyproject.toml").is_file()
if _checkout:
    __path__.append(str(_here.parent))


def _version() -> str:
    """The version pyproject.toml states, its one home: read from the file in a checkout (so
    that an edit shows without a reinstall), from the installed metadata otherwise."""
    if _checkout:
        text = (_here.parent / "pyproject.toml").read_text(encoding="utf-8")
        found = re.search(r'^version\s*=\s*"([^"]+)"', text, re.MULTILINE)
        if found:
            return found.group(1)
    from importlib.metadata import version

    return version("dfrl")


__version__ = _version()

from dfrl.robots.registration import ENV_ID, register_envs  # noqa: E402

register_envs()

#: Public name -> module that defines it (imported lazily by __getattr__).
_API: dict[str, str] = {
    "TrainerConfig": "dfrl.robots.training",
    "Trainer": "dfrl.robots.training",
    "train": "dfrl.robots.training",
    "load_arena": "dfrl.arenas.spec",
    "ExperimentConfig": "dfrl.experiments.driver.config",
    "RobotSpec": "dfrl.experiments.driver.config",
    "run_experiment": "dfrl.experiments.driver.launcher",
}

__all__ = [
    "ENV_ID",
    "__version__",
    "TrainerConfig",
    "Trainer",
    "train",
    "load_arena",
    "ExperimentConfig",
    "RobotSpec",
    "run_experiment",
]


def __getattr__(name: str) -> Any:
    module = _API.get(name)
    if module is None:
        raise AttributeError(f"module 'dfrl' has no attribute {name!r}")
    attr = "run" if name == "run_experiment" else name
    value = getattr(importlib.import_module(module), attr)
    globals()[name] = value
    return value
