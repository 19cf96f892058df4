"""Experiment and robot-node configuration: the dataclasses, their JSON form, where configs
live; every check is in :mod:`dfrl.experiments.driver.config_check`, the generic dataclass <-> dict
helpers in :mod:`dfrl.experiments.driver.config_dicts`. :class:`ExperimentConfig` (with its
:class:`RobotSpec` and :class:`JoinSpec` entries) defines a federated experiment and is saved
as ``config.json`` beside its results; :class:`RobotConfig` is
what the launcher hands one robot node process. :func:`resolve_config` finds a config file by
path or by the name of a shipped one (``experiments/configs``).
"""
from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from enum import Enum
from pathlib import Path
from typing import Any

from dfrl.experiments.driver.config_check import (BUILTIN_METHODS, ConfigError, check_experiment,
                                           check_node)
from dfrl.experiments.driver.config_dicts import config_from_dict, config_to_dict, raw_fields

__all__ = ["BUILTIN_METHODS", "ConfigError", "ExperimentConfig", "JoinSpec", "Mode",
           "RobotConfig", "RobotSpec", "boundaries", "parse_node", "resolve_config"]


class Mode(str, Enum):
    """How robots pace themselves against the agent."""

    ASYNC = "async"
    SYNC = "sync"


@dataclass(frozen=True)
class RobotConfig:
    """Everything one robot node process needs (written as JSON by the launcher).

    Attributes
    ----------
    robot : str
        Robot id, an atom in Prolog (``r1``).
    out_dir : str
        Results folder (metrics and shares CSVs are written there).
    arena, algo, seed, iterations
        Training run (see :class:`dfrl.robots.training.TrainerConfig`).
    respite : int
        Iterations between two shares (sync boundaries).
    mode : Mode
    rtf : float or None
        Real-time factor: 1.0 = one iteration per 64 ms of wall time; None or 0 = flat out.
    token : int, str or None
        Platform token agents must carry. None (the default, and always in the file the
        launcher writes: :meth:`public_dict`): the process reads it from its environment
        (``DFRL_TOKEN``, :mod:`dfrl.experiments.tokens`).
    trainer : dict
        Extra :class:`dfrl.robots.training.TrainerConfig` fields (``learner``,
        ``discretisation``, ...).
    grace_s : float
        Seconds the node stays up after its last iteration (see module doc).
    sync_timeout_s : float
        Longest wait for a share at a sync boundary before training goes on without it.
    progress_every : int
        Iterations between two ``DFRL_PROGRESS`` lines (0: none).
    events : bool
        Print ``DFRL_EVENT`` lines.
    bench_table : list of int or None
        ``[S, A]``: no simulation; serve a random table of that shape until stdin closes.
    host, tls : str, str or None
        Address to bind; a node's TLS folder (``dfrl certs node``; None: plaintext).
    eval_every, eval_steps : int
        Greedy evaluation of the table every ``eval_every`` iterations (0: none) for
        ``eval_steps`` control steps, in an environment of its own (:mod:`.robot_node.evaluate`).
    """

    robot: str
    out_dir: str
    arena: str = "r4"
    algo: str = "qlearning"
    seed: int = 0
    iterations: int = 8000
    respite: int = 500
    mode: Mode = Mode.ASYNC
    rtf: float | None = None
    token: int | str | None = None
    trainer: dict[str, Any] = field(default_factory=dict)
    grace_s: float = 10.0
    sync_timeout_s: float = 300.0
    progress_every: int = 100
    events: bool = True
    bench_table: list[int] | None = None
    host: str = "127.0.0.1"
    tls: str | None = None
    eval_every: int = 0
    eval_steps: int = 500

    def __post_init__(self) -> None:
        problems = check_node(raw_fields(self))
        if problems:
            raise ConfigError(problems)
        object.__setattr__(self, "mode", Mode(self.mode))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the token included: :meth:`public_dict` for files)."""
        return config_to_dict(self)

    def public_dict(self) -> dict[str, Any]:
        """:meth:`to_dict` without the token: what a results file or a peer may see."""
        return _without_token(config_to_dict(self))

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "RobotConfig":
        """Inverse of :meth:`to_dict` (unknown keys are an error)."""
        return config_from_dict(cls, data, check_node(data))

    def trainer_config(self):  # noqa: ANN201 - TrainerConfig (imported lazily)
        """The :class:`dfrl.robots.training.TrainerConfig` of this robot."""
        from dfrl.robots.training import TrainerConfig

        base = TrainerConfig().to_dict()
        base.update(self.trainer)
        base.update(arena=self.arena, algo=self.algo, seed=self.seed, iterations=self.iterations)
        return TrainerConfig.from_dict(base)


def _without_token(data: dict[str, Any]) -> dict[str, Any]:
    data.pop("token", None)
    return data


def boundaries(iterations: int, respite: int) -> list[int]:
    """Iterations at which a sync robot waits for a share: ``k * respite`` and the last one.

    >>> boundaries(1200, 500)
    [500, 1000, 1200]
    """
    points = list(range(respite, iterations + 1, respite))
    if iterations > 0 and (not points or points[-1] != iterations):
        points.append(iterations)
    return points


@dataclass(frozen=True)
class RobotSpec:
    """One robot of an experiment.

    Attributes
    ----------
    id : str
        Robot id (an atom in Prolog): lower case, e.g. ``r1``.
    arena : str
        Arena name or file.
    algo : str
        ``qlearning`` or ``sarsa``.
    seed : int or None
        None: the experiment seed plus the robot's position in the list.
    node : str or None
        ``"HOST:PORT"`` of an already running ``dfrl robot`` that runs this robot (configured
        over the platform); None: the launcher spawns a robot process on its own host.
    """

    id: str
    arena: str
    algo: str = "qlearning"
    seed: int | None = None
    node: str | None = None

    def __post_init__(self) -> None:
        raw = raw_fields(self)
        problems = check_experiment({"robots": [raw]}, resources=False)
        if problems:
            raise ConfigError([p.removeprefix("robots[0].") for p in problems])

    @property
    def node_address(self) -> tuple[str, int] | None:
        """``(host, port)`` of the robot's ``dfrl robot`` service, None when spawned locally."""
        return parse_node(self.node) if self.node is not None else None


def parse_node(text: str) -> tuple[str, int]:
    """``"HOST:PORT"`` -> ``(host, port)``, e.g. ``('10.0.0.7', 7001)``.

    Raises
    ------
    ValueError
        Not a host and a port 1..65535.
    """
    host, sep, port = str(text).rpartition(":")
    if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise ValueError(f"robot node {text!r}: use HOST:PORT, e.g. 10.0.0.7:7001")
    return host.strip("[]"), int(port)


@dataclass(frozen=True)
class JoinSpec:
    """A robot that joins the running experiment once ``after_round`` rounds are logged."""

    robot: RobotSpec
    after_round: int = 1


@dataclass(frozen=True)
class ExperimentConfig:
    """Everything that defines a federated experiment (saved as ``config.json``).

    Attributes
    ----------
    name : str
    robots : tuple of RobotSpec
        In itinerary order (per algorithm).
    iterations : int
        Control iterations per robot.
    respite : int
        Iterations between two shares: the number of agent rounds is
        ``ceil(iterations / respite)``.
    seed : int
    mode : Mode
        ``sync`` (default: robots wait for the agent at each respite boundary, so the same
        config and seed give the same curves, the reproducible setting) or ``async`` (robots
        run flat out and serve the agent between steps; wall-clock timing shapes the rounds).
    rtf : float or None
        Real-time factor (1.0: one iteration per 64 ms of wall time); None: flat out.
    method : str
        Aggregation method of every agent, unless ``methods`` names one for its algorithm.
    methods : dict
        Algorithm -> method.
    rest_s : float or None
        Async only: seconds the agent rests at its first stop between rounds. None: the
        expected wall time of one respite.
    token : int, str or None
        The platform token of the run's nodes: an integer >= 0 or a string without white
        space. None (the default): ``dfrl run`` makes a strong random one for each run
        (``dfrl_`` and 64 hex digits, :func:`dfrl.experiments.cli.secret.new_secret`). It is
        never written to ``config.json`` (:meth:`public_dict`); the run keeps it in
        ``secret.token`` (mode 0600). A weak token (``1111``) serves on loopback only; robots
        on other hosts need the strong token their ``dfrl robot`` was started with.
    trainer : dict
        Extra :class:`dfrl.robots.training.TrainerConfig` fields shared by all robots.
    joins : tuple of JoinSpec
    timeout_s : float
        Whole-experiment limit (children are killed after it). The default, 3600 s, is a safety
        ceiling for the default 8000 iterations on a loaded machine; the shipped configs set
        their own (``demo``: 900 s, the budget of a 5-robot demo; the ``paper_*`` configs keep
        3600 s).
    title : str
        Plot title (default: derived from the config).
    console : str or None
        Address the launcher's console node binds and the robots reach it at. None: the
        address this host uses towards the first remote robot (its route), or 127.0.0.1 when
        every robot is spawned locally.
    tolerate_lost_robots : int
        Robots that may be lost (crashed, failed, unreachable at the end) with the run still
        counted as complete.
    tolerate_missing_rounds : int
        Planned rounds per agent that may be missing (never logged) likewise.
    tolerate_method_errors : int
        Rounds per agent whose aggregation method may fail (the round is aborted: no table is
        written) with the run still counted as complete.
    eval_every, eval_steps : int
        Every robot measures its greedy policy every ``eval_every`` iterations (0: never) for
        ``eval_steps`` control steps (``eval_<robot>.csv``, ``live_evaluations.csv``).
    """

    name: str = "experiment"
    robots: tuple[RobotSpec, ...] = ()
    iterations: int = 8000
    respite: int = 500
    seed: int = 1
    mode: Mode = Mode.SYNC
    rtf: float | None = None
    method: str = "average"
    methods: dict[str, str] = field(default_factory=dict)
    rest_s: float | None = None
    token: int | str | None = None
    trainer: dict[str, Any] = field(default_factory=dict)
    joins: tuple[JoinSpec, ...] = ()
    timeout_s: float = 3600.0
    title: str = ""
    console: str | None = None
    tolerate_lost_robots: int = 0
    tolerate_missing_rounds: int = 0
    tolerate_method_errors: int = 0
    eval_every: int = 0
    eval_steps: int = 500

    def __post_init__(self) -> None:
        raw = raw_fields(self)
        raw["robots"] = [raw_fields(r) if isinstance(r, RobotSpec) else r for r in self.robots]
        raw["joins"] = [{"robot": j.robot, "after_round": j.after_round}
                        if isinstance(j, JoinSpec) else j for j in self.joins]
        raw["joins"] = [dict(j, robot=raw_fields(j["robot"])) if isinstance(j, dict)
                        and isinstance(j.get("robot"), RobotSpec) else j for j in raw["joins"]]
        problems = check_experiment(raw, resources=False)
        if problems:
            raise ConfigError(problems)
        object.__setattr__(self, "mode", Mode(self.mode))
        object.__setattr__(self, "robots", tuple(
            r if isinstance(r, RobotSpec) else RobotSpec(**r) for r in self.robots))
        object.__setattr__(self, "joins", tuple(
            j if isinstance(j, JoinSpec) else
            JoinSpec(robot=j["robot"] if isinstance(j["robot"], RobotSpec)
                     else RobotSpec(**j["robot"]),
                     after_round=int(j.get("after_round", 1)))
            for j in self.joins))

    def check(self) -> None:
        """Check what :meth:`from_dict` leaves to run time: every arena exists and parses.

        Raises
        ------
        ConfigError
            With every problem and its key path.
        """
        problems = check_experiment(self.to_dict(), resources=True)
        if problems:
            raise ConfigError(problems)

    # -- derived -------------------------------------------------------------------------------
    @property
    def rounds(self) -> int:
        """Agent rounds: one per respite boundary (the last iteration included)."""
        return len(boundaries(self.iterations, self.respite))

    def remote_robots(self) -> list[RobotSpec]:
        """Robots (and joiners) that run on an already running ``dfrl robot``."""
        return [r for r in list(self.robots) + [j.robot for j in self.joins] if r.node]

    def algorithms(self) -> list[str]:
        """Algorithms in order of first appearance (one agent each)."""
        seen: list[str] = []
        for r in list(self.robots) + [j.robot for j in self.joins]:
            if r.algo not in seen:
                seen.append(r.algo)
        return seen

    def method_for(self, algo: str) -> str:
        return self.methods.get(algo, self.method)

    def robot_seed(self, robot: RobotSpec) -> int:
        if robot.seed is not None:
            return robot.seed
        ids = [r.id for r in self.robots] + [j.robot.id for j in self.joins]
        return self.seed + ids.index(robot.id)

    def default_title(self) -> str:
        if self.title:
            return self.title
        algos = "+".join({"qlearning": "Q-learning", "sarsa": "SARSA"}.get(a, a)
                         for a in self.algorithms())
        methods = "/".join(sorted({self.method_for(a) for a in self.algorithms()}))
        return (f"dFRL {algos}, {methods}, {len(self.robots)} robots, "
                f"{self.iterations} iterations, respite {self.respite} ({self.mode.value})")

    # -- (de)serialisation ---------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the token included: :meth:`public_dict` for files)."""
        return config_to_dict(self)

    def public_dict(self) -> dict[str, Any]:
        """:meth:`to_dict` without the token: what ``config.json`` of a results folder holds."""
        return _without_token(config_to_dict(self))

    @classmethod
    def from_dict(cls, data: dict[str, Any], resources: bool = False) -> "ExperimentConfig":
        """Inverse of :meth:`to_dict`; every problem of ``data`` is reported at once
        (``resources``: the arenas too).

        Raises
        ------
        ConfigError
        """
        return config_from_dict(cls, data, check_experiment(data, resources=resources))

    @classmethod
    def load(cls, path: str | Path, overrides: dict[str, Any] | None = None,
             resources: bool = True) -> "ExperimentConfig":
        """Read a config file, apply ``overrides`` (top-level keys) and check it all.

        Raises
        ------
        ConfigError
            Not JSON, or any problem of the config (each with its key path), the file named.
        """
        try:
            data = json.loads(Path(path).read_text(encoding="utf-8"))
        except json.JSONDecodeError as exc:
            raise ConfigError([f"not valid JSON: {exc}"], str(path)) from None
        except OSError as exc:
            raise ConfigError([f"cannot read it: {exc.strerror}"], str(path)) from None
        if isinstance(data, dict) and overrides:
            data = {**data, **overrides}
        try:
            return cls.from_dict(data, resources=resources)
        except ConfigError as exc:
            raise ConfigError(exc.problems, str(path)) from None

    def replace(self, **changes: Any) -> "ExperimentConfig":
        return dataclasses.replace(self, **changes)


CONFIGS_DIR: Path = Path(__file__).resolve().parent.parent / "configs"


def resolve_config(name: str) -> Path:
    """A config file path, or the name of one in ``experiments/configs`` (``.json`` optional)."""
    p = Path(name)
    if p.is_file():
        return p
    for cand in (CONFIGS_DIR / name, CONFIGS_DIR / f"{name}.json"):
        if cand.is_file():
            return cand
    raise FileNotFoundError(f"no config {name!r} (neither a file nor one of "
                            f"{sorted(q.stem for q in CONFIGS_DIR.glob('*.json'))})")
