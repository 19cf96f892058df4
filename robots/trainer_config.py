"""What defines a training run: :class:`TrainerConfig` (environment, learner, seed, budget).

Imported by :mod:`dfrl.robots.training`, where callers usually take it from.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from enum import Enum
from typing import Any

from dfrl.robots.dqn import DQNConfig
from dfrl.robots.env import EnvConfig, RewardConfig
from dfrl.robots.epuck import EPuckConfig
from dfrl.robots.learners import EpsilonSchedule, LearnerParams
from dfrl.robots.linear import LinearConfig
from dfrl.robots.reward_shuffle import DEFAULT_MODE, shuffle_mode
from dfrl.robots.state import DiscretisationConfig
from dfrl.robots.world import SimConfig

#: Training budget (iterations) of the 5-robot demo: learning clearly shows by then.
DEMO_ITERATIONS: int = 8000


@dataclass(frozen=True)
class TrainerConfig(EnvConfig):
    """Everything that defines a training run; the same config and seed give the same run.

    The environment's fields (arena, sim, actions, reward, collision response, stuck
    detector) come from :class:`dfrl.robots.env.EnvConfig`; the learner's are added here.

    Attributes
    ----------
    arena : str
        Built-in arena name or arena file path.
    algo : str
        Learner name, a key of :data:`dfrl.robots.learners.LEARNERS`.
    seed : int
        Seeds the environment (start/respawn poses, sensor noise) and the learner
        (exploration) through independent streams.
    iterations : int
        Budget used by :func:`train` (a :class:`Trainer` can step beyond it).
    learner : LearnerParams
    discretisation : DiscretisationConfig
        The tabular learners' states (the function learners see the raw observation; the
        discrete state is still reported in the metrics).
    linear : LinearConfig
        The ``linear`` learner's step size and feature map.
    dqn : DQNConfig
        The ``dqn`` learner's network, replay and optimiser.
    reward_shuffle : int
        0 (the default): the learner learns from the reward the robot earned. ``W > 0``: the
        learning control, the learner learns from outcomes (reward and end-of-episode flag)
        drawn through a shuffle buffer of ``W`` observed ones
        (:class:`dfrl.robots.reward_shuffle.RewardShuffle`, drawn from a third stream of
        ``seed``), so that nothing it learns depends on the state and action; the metrics still
        record the reward earned. Any learner.
    reward_shuffle_mode : str
        What the control learns from the drawn outcome, a
        :class:`dfrl.robots.reward_shuffle.ShuffleMode` value: ``"centred_no_bootstrap"`` (the
        default: the reward minus the buffer's mean, every update terminal), ``"centred"``
        (the end flag drawn with it, bootstrapping kept) or ``"raw"`` (the outcome as drawn:
        the control before issue 34, which configurations written before it meant). Only
        used with ``reward_shuffle > 0``.
    sim : SimConfig
        Control/physics rates, solver, robot.
    actions : ActionSet
    reward : RewardConfig
    collision_response : CollisionResponse
    stuck_steps : int
    stuck_distance : float
    """

    algo: str = "qlearning"
    seed: int = 0
    iterations: int = DEMO_ITERATIONS
    learner: LearnerParams = field(default_factory=LearnerParams)
    discretisation: DiscretisationConfig = field(default_factory=DiscretisationConfig)
    linear: LinearConfig = field(default_factory=LinearConfig)
    dqn: DQNConfig = field(default_factory=DQNConfig)
    reward_shuffle: int = 0
    reward_shuffle_mode: str = DEFAULT_MODE.value

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.iterations < 0:
            raise ValueError("iterations must be >= 0")
        if not isinstance(self.reward_shuffle, int) or self.reward_shuffle < 0:
            raise ValueError(
                f"reward_shuffle must be an int >= 0 (0: off), got {self.reward_shuffle!r}"
            )
        object.__setattr__(
            self, "reward_shuffle_mode", shuffle_mode(self.reward_shuffle_mode).value
        )

    def env_config(self) -> EnvConfig:
        """The environment part of the configuration."""
        env = {f.name: getattr(self, f.name) for f in dataclasses.fields(EnvConfig)}
        env["arena"] = str(self.arena)
        return EnvConfig(**env)

    def to_dict(self, full: bool = False) -> dict[str, Any]:
        """JSON-ready nested dict (enums as their values).

        ``reward_shuffle`` and ``reward_shuffle_mode`` are left out while the control is off
        (``reward_shuffle`` 0) unless ``full``: the JSON of every ordinary configuration, and
        every name hashed from it (reference tables), stays as it was before the options
        existed; ``full`` lists every field (what a config checker accepts). With the control
        on, both are written, so a run's ``config.json`` says which control it ran."""
        d = to_jsonable(self)
        if not full and not self.reward_shuffle:
            d.pop("reward_shuffle")
            d.pop("reward_shuffle_mode")
        return d

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "TrainerConfig":
        """Inverse of :meth:`to_dict`."""
        d = dict(data)
        learner = dict(d.pop("learner", {}))
        if "epsilon" in learner:
            learner["epsilon"] = EpsilonSchedule(**learner["epsilon"])
        sim = dict(d.pop("sim", {}))
        if "robot" in sim:
            robot = dict(sim["robot"])
            if "sensor_angles" in robot:
                robot["sensor_angles"] = tuple(robot["sensor_angles"])
            sim["robot"] = EPuckConfig(**robot)
        return cls(
            learner=LearnerParams(**learner),
            discretisation=DiscretisationConfig(**d.pop("discretisation", {})),
            linear=LinearConfig(**d.pop("linear", {})),
            dqn=DQNConfig(**d.pop("dqn", {})),
            sim=SimConfig(**sim),
            reward=RewardConfig(**d.pop("reward", {})),
            **d,
        )

    def replace(self, **changes: Any) -> "TrainerConfig":
        """A copy with some fields changed."""
        return dataclasses.replace(self, **changes)


def to_jsonable(obj: Any) -> Any:
    """Dataclasses as dicts, enums as their values, tuples as lists, recursively."""
    if dataclasses.is_dataclass(obj):
        return {f.name: to_jsonable(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, Enum):
        return obj.value
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    return obj


def with_params_meta(config: TrainerConfig, meta: Any) -> TrainerConfig:
    """``config`` with the learner a parameter file was saved from: its ``algo`` and its own
    configuration (``meta`` is a :class:`dfrl.robots.tables.ParamsMeta`).

    Raises
    ------
    KeyError
        The file's learner is not registered.
    TypeError, ValueError
        Its configuration does not fit the learner's.
    """
    from dfrl.robots.learners import learner_class

    field_name = getattr(learner_class(meta.algo), "config_field", None)
    changes: dict[str, Any] = {"algo": meta.algo}
    if field_name:
        changes[field_name] = type(getattr(config, field_name))(**meta.model)
    return config.replace(**changes)
