"""Experiment configuration: :class:`ExperimentConfig` (with its :class:`RobotSpec` and
:class:`JoinSpec` entries) defines a federated experiment and is saved as ``config.json`` beside
its results; :func:`resolve_config` finds a config file by path or by the name of a shipped one
(``experiments/configs``). Every check is in :mod:`dfrl.experiments.driver.config_check`; the
config of one robot process is :class:`dfrl.experiments.robot_host.config.RobotConfig`.

A config is checked once: :meth:`ExperimentConfig.from_dict` (and :meth:`~ExperimentConfig.load`)
check its JSON form as a whole and build it with ``_checked=True`` (a keyword-only init-only
field: the whole was checked), which it passes on to the entries it builds; a config built in
Python without it checks itself in ``__post_init__``; :meth:`~ExperimentConfig.check` loads
the arenas unless that was done already; :meth:`~ExperimentConfig.with_token` checks the token
alone.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import KW_ONLY, InitVar, dataclass, field
from pathlib import Path
from typing import Any

from dfrl.experiments.config_rules import (
    JsonDicts,
    ConfigError,
    check_value,
    json_form,
    raise_problems,
    resolve_trainer,
    token_rule,
)
from dfrl.experiments.driver.config_check import (
    BUILTIN_METHODS,
    COMMENT_KEYS,
    GRID,
    check_experiment,
    host_port_problem,
)
from dfrl.experiments.robot_host.config import DEFAULT_ITERATIONS, Mode, boundaries

__all__ = [
    "BUILTIN_METHODS",
    "CONFIGS_DIR",
    "GRID",
    "ConfigError",
    "ExperimentConfig",
    "JoinSpec",
    "RobotSpec",
    "parse_host_port",
    "resolve_config",
]


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
        A registered learner: ``qlearning``, ``sarsa``, ``linear`` or ``dqn``.
    seed : int or None
        None: the experiment seed plus the robot's position in the list.
    robot_host : str or None
        ``"HOST:PORT"`` of an already running ``dfrl robot`` service that runs this robot
        (configured over the platform); None: the launcher spawns a robot process on its own
        host.
    """

    id: str
    arena: str
    algo: str = "qlearning"
    seed: int | None = None
    robot_host: str | None = None
    _: KW_ONLY
    _checked: InitVar[bool] = False  # True: checked as part of its config's JSON form

    def __post_init__(self, _checked: bool) -> None:
        if not _checked:
            problems = check_experiment({"robots": [json_form(self)]}, resources=False)
            raise_problems([p.removeprefix("robots[0].") for p in problems])

    @property
    def robot_host_address(self) -> tuple[str, int] | None:
        """``(host, port)`` of the robot's ``dfrl robot`` service, None when spawned locally."""
        return parse_host_port(self.robot_host) if self.robot_host is not None else None


def parse_host_port(text: str) -> tuple[str, int]:
    """``"HOST:PORT"`` (of a robot host) -> ``(host, port)``, e.g. ``('10.0.0.7', 7001)``.

    Raises
    ------
    ValueError
        Not a host and a port 1..65535.
    """
    why = host_port_problem(str(text))
    if why is not None:
        raise ValueError(why)
    host, _, port = str(text).rpartition(":")
    return host.strip("[]"), int(port)


@dataclass(frozen=True)
class JoinSpec:
    """A robot that joins the running experiment once ``after_round`` rounds are logged."""

    robot: RobotSpec
    after_round: int = 1


@dataclass(frozen=True)
class ExperimentConfig(JsonDicts):
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
        Extra :class:`dfrl.robots.training.TrainerConfig` fields shared by all robots (nested
        ones as objects; a field not given keeps its default). ``config.json`` of a results
        folder lists them all (:meth:`resolved`).
    joins : tuple of JoinSpec
    timeout_s : float
        Whole-experiment limit (children are killed after it). The default, 3600 s, is a safety
        ceiling for the default 8000 iterations on a loaded machine; the shipped configs set
        their own (``demo``: 900 s, the budget of a 5-robot demo; the ``paper_*`` configs keep
        3600 s).
    skip_after_s : float
        The most the agent spends on one move to a stop it cannot reach (all its tries
        together) before it skips the stop for that round (default 4 s).
    partition_wait_s : float
        How long the driver holds back calling robots on robot hosts LOST when it reaches none
        of them (at least two; none answered since the first went silent): its own host is
        probably cut off, not theirs. It says ``driver partitioned`` and waits; when one
        answers again the run goes on; after this long they are LOST (default 120 s).
    title : str
        Plot title (default: derived from the config).
    console : str or None
        Address the launcher's console node binds and the robots reach it at. None: the
        address this host uses towards the first remote robot (its route), or 127.0.0.1 when
        every robot is spawned locally.
    tolerate_lost_robots : int
        Robots that may be lost (crashed, failed, unreachable at the end) or skipped by their
        agent in some round with the run still counted as complete.
    tolerate_missing_rounds : int
        Planned rounds per agent that may be missing (never logged) likewise.
    tolerate_method_errors : int
        Rounds per agent whose aggregation method may fail (the round is aborted: no table is
        written) with the run still counted as complete.
    eval_every, eval_steps : int
        Every robot measures its greedy policy every ``eval_every`` iterations (0: never) for
        ``eval_steps`` control steps (``eval_<robot>.csv``, ``live_evaluations.csv``).
    federation : str
        ``per_algorithm`` (default): one agent per algorithm, carrying Q-tables (tabular
        learners) or parameter vectors (function learners). ``grid``: one agent over every
        robot, whatever its learner, carrying Q-tables on the discretised state grid: a
        function learner's table is its Q-function at the grid's points and it absorbs the
        aggregate by distillation (:mod:`dfrl.robots.grid_view`); ``methods`` and ``joins``
        are refused there.
    itinerary : str
        How each agent goes over its robots in a round: ``chain`` (default: one walk along
        the robots and back) or ``tree`` (the agent clones itself over a tree of the robots,
        ``fanout`` children per stop; every robot still ends the round with the same table).
    fanout : int
        Children of each stop in a ``tree`` itinerary (>= 2, default 2).
    learners : dict
        Plug-in learners the robots may name in ``algo``: ``name -> "module:Class"``,
        ``"file.py:Class"`` (relative to the config file) or ``{"class": ..., "options":
        {...}}`` (:mod:`dfrl.robots.plugins`; robots/README.md, "Bring your own learner").
    """

    name: str = "experiment"
    robots: tuple[RobotSpec, ...] = ()
    iterations: int = DEFAULT_ITERATIONS
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
    skip_after_s: float = 4.0
    partition_wait_s: float = 120.0
    title: str = ""
    console: str | None = None
    tolerate_lost_robots: int = 0
    tolerate_missing_rounds: int = 0
    tolerate_method_errors: int = 0
    eval_every: int = 0
    eval_steps: int = 500
    federation: str = "per_algorithm"
    itinerary: str = "chain"
    fanout: int = 2
    learners: dict[str, Any] = field(default_factory=dict)
    _: KW_ONLY
    _checked: InitVar[bool] = False  # True: its JSON form was checked as a whole

    def __post_init__(self, _checked: bool) -> None:
        if not _checked:
            raise_problems(check_experiment(json_form(self), resources=False))
        # the entries were part of the whole: built without checking again
        object.__setattr__(self, "mode", Mode(self.mode))
        object.__setattr__(self, "robots", tuple(_robot(r) for r in self.robots))
        object.__setattr__(
            self,
            "joins",
            tuple(
                j
                if isinstance(j, JoinSpec)
                else JoinSpec(robot=_robot(j["robot"]), after_round=int(j.get("after_round", 1)))
                for j in self.joins
            ),
        )

    def check(self) -> None:
        """Check what :meth:`from_dict` may leave to run time: every arena exists and parses
        (nothing when that was checked already, by :meth:`load` or an earlier call).

        Raises
        ------
        ConfigError
            With every problem and its key path.
        """
        if not getattr(self, "_arenas_checked", False):
            raise_problems(check_experiment(self.to_dict(), resources=True))
            object.__setattr__(self, "_arenas_checked", True)

    # -- derived -------------------------------------------------------------------------------
    @property
    def rounds(self) -> int:
        """Agent rounds: one per respite boundary (the last iteration included)."""
        return len(boundaries(self.iterations, self.respite))

    def remote_robots(self) -> list[RobotSpec]:
        """Robots (and joiners) that run on an already running ``dfrl robot``."""
        return [r for r in list(self.robots) + [j.robot for j in self.joins] if r.robot_host]

    def algorithms(self) -> list[str]:
        """Algorithms in order of first appearance (one agent each)."""
        seen: list[str] = []
        for r in list(self.robots) + [j.robot for j in self.joins]:
            if r.algo not in seen:
                seen.append(r.algo)
        return seen

    def method_for(self, algo: str) -> str:
        """The method of the agent of ``algo`` (or of the grid federation's, ``GRID``)."""
        return self.methods.get(algo, self.method)

    def agent_groups(self) -> list[tuple[str, tuple[str, ...]]]:
        """``(label, algorithms)`` per agent, in launch order: one per algorithm (the label is
        the algorithm), or in a grid federation one labelled ``GRID`` over every algorithm."""
        if self.federation == GRID:
            return [(GRID, tuple(self.algorithms()))]
        return [(a, (a,)) for a in self.algorithms()]

    def robot_seed(self, robot: RobotSpec) -> int:
        if robot.seed is not None:
            return robot.seed
        ids = [r.id for r in self.robots] + [j.robot.id for j in self.joins]
        return self.seed + ids.index(robot.id)

    def resolved(self) -> "ExperimentConfig":
        """This config with what a run fills in written out (what ``config.json`` of a
        results folder holds): every robot's and joiner's ``seed`` as the run uses it
        (:meth:`robot_seed`) and ``trainer`` with every
        :class:`~dfrl.robots.training.TrainerConfig` field, defaults included
        (:func:`~dfrl.experiments.config_rules.resolve_trainer`). It runs exactly as this
        one (the same seeds, the same trainers) and resolves to itself."""
        # seeds >= 0 and a trainer the checks accept: not checked again
        robots = tuple(
            dataclasses.replace(r, seed=self.robot_seed(r), _checked=True) for r in self.robots
        )
        joins = tuple(
            dataclasses.replace(
                j, robot=dataclasses.replace(j.robot, seed=self.robot_seed(j.robot), _checked=True)
            )
            for j in self.joins
        )
        cfg = dataclasses.replace(
            self, robots=robots, joins=joins, trainer=resolve_trainer(self.trainer), _checked=True
        )
        object.__setattr__(cfg, "_arenas_checked", getattr(self, "_arenas_checked", False))
        return cfg

    def default_title(self) -> str:
        if self.title:
            return self.title
        algos = "+".join(
            {"qlearning": "Q-learning", "sarsa": "SARSA"}.get(a, a) for a in self.algorithms()
        )
        methods = "/".join(sorted({self.method_for(a) for a in self.algorithms()}))
        return (
            f"dFRL {algos}, {methods}, {len(self.robots)} robots, "
            f"{self.iterations} iterations, respite {self.respite} ({self.mode.value})"
        )

    # -- (de)serialisation ---------------------------------------------------------------------
    @classmethod
    def from_dict(cls, data: dict[str, Any], resources: bool = False) -> "ExperimentConfig":
        """Inverse of :meth:`to_dict`; every problem of ``data`` is reported at once
        (``resources``: the arenas too).

        Raises
        ------
        ConfigError
        """
        raise_problems(check_experiment(data, resources=resources))
        cfg = cls(**{k: v for k, v in data.items() if k not in COMMENT_KEYS}, _checked=True)
        object.__setattr__(cfg, "_arenas_checked", resources)
        return cfg

    @classmethod
    def load(
        cls, path: str | Path, overrides: dict[str, Any] | None = None, resources: bool = True
    ) -> "ExperimentConfig":
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
        if isinstance(data, dict) and "learners" in data:  # files beside the config
            from dfrl.robots.plugins import absolute_section

            data = {
                **data,
                "learners": absolute_section(data["learners"], Path(path).resolve().parent),
            }
        try:
            return cls.from_dict(data, resources=resources)
        except ConfigError as exc:
            raise ConfigError(exc.problems, str(path)) from None

    def replace(self, **changes: Any) -> "ExperimentConfig":
        """A copy with ``changes``, checked as a whole (as a config built in Python)."""
        return dataclasses.replace(self, **changes)

    def with_token(self, token: int | str | None) -> "ExperimentConfig":
        """A copy with ``token``, only the token checked (the rest was, and has not changed).

        Raises
        ------
        ConfigError
            ``token: not a token: ...``.
        """
        raise_problems(check_value("token", token, token_rule()))
        cfg = dataclasses.replace(self, token=token, _checked=True)
        object.__setattr__(cfg, "_arenas_checked", getattr(self, "_arenas_checked", False))
        return cfg


def _robot(entry: RobotSpec | dict[str, Any]) -> RobotSpec:
    """An entry of a config checked as a whole (a dict is not checked again)."""
    return entry if isinstance(entry, RobotSpec) else RobotSpec(**entry, _checked=True)


CONFIGS_DIR: Path = Path(__file__).resolve().parent.parent / "configs"


def resolve_config(name: str) -> Path:
    """A config file path, or the name of one in ``experiments/configs`` (``.json`` optional)."""
    p = Path(name)
    if p.is_file():
        return p
    for cand in (CONFIGS_DIR / name, CONFIGS_DIR / f"{name}.json"):
        if cand.is_file():
            return cand
    from dfrl.experiments.suggestions import did_you_mean

    known = sorted(q.stem for q in CONFIGS_DIR.glob("*.json"))
    near = did_you_mean(name.removesuffix(".json"), known)
    raise FileNotFoundError(
        f"no config {name!r} (neither a file nor one of {known})" + (f"; {near}" if near else "")
    )
