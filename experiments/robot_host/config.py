"""The config of one robot process (:class:`RobotConfig`, written as JSON by the launcher or
sent to a ``dfrl robot`` service), its pacing :class:`Mode` and the sync :func:`boundaries`.

Checked with the rules of :mod:`dfrl.experiments.config_rules` (every problem at once, each
with its key path), so a robot host needs nothing of the driver.
"""

from __future__ import annotations

from dataclasses import KW_ONLY, InitVar, dataclass, field
from enum import Enum
from typing import Any

from dfrl.experiments.config_rules import (
    JsonDicts,
    Rule,
    check_keys,
    check_robot_id,
    check_trainer,
    json_form,
    known_algorithms,
    raise_problems,
    token_rule,
)
from dfrl.experiments.robot_host.static_robot import static_problems

__all__ = ["DEFAULT_ITERATIONS", "Mode", "RobotConfig", "boundaries", "check_robot_config"]

#: Control iterations of a robot unless a config says otherwise (64 ms of simulated time each).
DEFAULT_ITERATIONS = 8000


class Mode(str, Enum):
    """How robots pace themselves against the agent."""

    ASYNC = "async"
    SYNC = "sync"


def modes() -> list[str]:
    return [m.value for m in Mode]


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
class RobotConfig(JsonDicts):
    """Everything one robot process needs (written as JSON by the launcher).

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
        Seconds the process stays up after its last iteration.
    sync_timeout_s : float
        Longest wait for a share at a sync boundary before training goes on without it.
    progress_every : int
        Iterations between two ``DFRL_PROGRESS`` lines (0: none).
    events : bool
        Print ``DFRL_EVENT`` lines.
    bench_table : list of int or None
        ``[S, A]``: a static robot (:mod:`.static_robot`), no simulation; serve a random table
        of that shape until stdin closes.
    bench_params : dict or None
        ``{"samples": N}``: a static robot, no simulation; serve a random parameter vector
        with the layout of the network of ``algo`` (a function learner: ``linear``, ``dqn``;
        its size from the ``trainer`` config), learnt from ``N`` samples (its FedAvg weight),
        until stdin closes. A robot has a bench table or bench params, not both.
    host, tls : str, str or None
        Address to bind; a node's TLS folder (``dfrl certs node``; None: plaintext).
    eval_every, eval_steps : int
        Greedy evaluation of the table every ``eval_every`` iterations (0: none) for
        ``eval_steps`` control steps, in an environment of its own (:mod:`.evaluate`).
    clone_limit : int or None
        Clones that may arrive at the robot's node per minute (the node's ``clone_limit``;
        None: the platform's default, 60). A tree itinerary's copies are clones.
    learners : dict
        The run's plug-in learners (``name -> {"class": spec, "options": {...}}``, the
        experiment's ``learners``), registered by the process before it builds its learner.

    Built in Python, a config checks itself (every problem at once); :meth:`from_dict` checks
    the JSON form and builds it with ``_checked=True`` (keyword only, not a field), so that it
    is checked once.
    """

    robot: str
    out_dir: str
    arena: str = "r4"
    algo: str = "qlearning"
    seed: int = 0
    iterations: int = DEFAULT_ITERATIONS
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
    bench_params: dict[str, int] | None = None
    host: str = "127.0.0.1"
    tls: str | None = None
    eval_every: int = 0
    eval_steps: int = 500
    clone_limit: int | None = None
    learners: dict[str, Any] = field(default_factory=dict)
    _: KW_ONLY
    _checked: InitVar[bool] = False

    def __post_init__(self, _checked: bool) -> None:
        if not _checked:
            raise_problems(check_robot_config(json_form(self)))
        object.__setattr__(self, "mode", Mode(self.mode))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (the token included); ``clone_limit`` only when set, so that a
        ``dfrl robot`` host of an earlier version, which refuses keys it does not know, still
        takes a chain run's config (``learners`` likewise, only when the run has plug-ins)."""
        data = super().to_dict()
        if data.get("clone_limit") is None:
            data.pop("clone_limit", None)
        if not data.get("learners"):
            data.pop("learners", None)
        return data

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "RobotConfig":
        """Inverse of :meth:`to_dict`; every problem of ``data`` is reported at once.

        Raises
        ------
        ConfigError
        """
        raise_problems(check_robot_config(data))
        return cls(**data, _checked=True)

    def trainer_config(self):  # noqa: ANN201 - TrainerConfig (imported lazily)
        """The :class:`dfrl.robots.training.TrainerConfig` of this robot."""
        from dfrl.robots.training import TrainerConfig

        base = TrainerConfig().to_dict()
        base.update(self.trainer)
        base.update(arena=self.arena, algo=self.algo, seed=self.seed, iterations=self.iterations)
        return TrainerConfig.from_dict(base)


_NO_EVAL = "0 means no evaluation"

RULES: dict[str, Rule] = {
    "robot": Rule(str),
    "out_dir": Rule(str),
    "arena": Rule(str),
    "algo": Rule(str, choices=known_algorithms, what="algorithm"),
    "seed": Rule(int, low=0),
    "iterations": Rule(int, low=0),
    "respite": Rule(int, low=1),
    "mode": Rule(str, choices=modes, what="mode"),
    "rtf": Rule(float, nullable=True, low=0, hint="null or 0 means flat out"),
    "token": token_rule(),
    "trainer": Rule(dict),
    "grace_s": Rule(float, low=0),
    "sync_timeout_s": Rule(float, above=0),
    "progress_every": Rule(int, low=0),
    "events": Rule(bool),
    "bench_table": Rule(list, nullable=True),
    "bench_params": Rule(dict, nullable=True),
    "host": Rule(str),
    "tls": Rule(str, nullable=True),
    "eval_every": Rule(int, low=0, hint=_NO_EVAL),
    "eval_steps": Rule(int, low=1),
    "clone_limit": Rule(int, nullable=True, low=1),
    "learners": Rule(dict, hint='plug-in learners: name -> {"class": spec, "options": {}}'),
}


def check_robot_config(data: Any) -> list[str]:
    """Every problem of a robot process config in its JSON form (empty: it can run)."""
    out: list[str] = []
    if isinstance(data, dict) and isinstance(data.get("learners"), dict):  # before algo
        from dfrl.robots.plugins import section_problems

        out += section_problems(data["learners"])
    out += check_keys("", data, RULES, required=("robot", "out_dir"))
    if not isinstance(data, dict):
        return out
    out += check_robot_id("robot", data.get("robot"))
    out += static_problems(data)
    if "trainer" in data:
        out += check_trainer("trainer", data["trainer"])
    return out
