"""The simulators a study runs on, and the rule that one study does not mix them.

* ``batched`` (the default, :data:`BATCHED`): :mod:`dfrl.robots.batched`, many tabular robots
  stepped together by compiled kernels (about 150 times the robot-steps per second of one
  pybullet robot); Q-learning and SARSA only;
* ``pybullet`` (:data:`PYBULLET`): :class:`dfrl.robots.training.Trainer`, the robots of
  ``dfrl run``; every learner.

A study records the simulator it ran on (``"sim"`` in its JSON, CSV and summary) and refuses to
add runs of one simulator to results of the other (:func:`check_same`). Results written before
the studies took ``--sim`` ran on pybullet (:data:`LEGACY_SIM`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from dfrl.experiments.science.studies.fedsim import Federation

#: The batched simulator's name (:data:`dfrl.robots.batched.training.SIM_NAME`).
BATCHED = "batched"
PYBULLET = "pybullet"
#: Choices of ``--sim``, the default first.
SIMS: tuple[str, ...] = (BATCHED, PYBULLET)
DEFAULT_SIM = BATCHED
#: The simulator of results recorded before the studies named theirs.
LEGACY_SIM = PYBULLET


class SimulatorMismatch(ValueError):
    """Results of one simulator meet options that ask for the other."""


def check_sim(sim: str) -> None:
    """Raises ValueError unless ``sim`` is one of :data:`SIMS`."""
    if sim not in SIMS:
        raise ValueError(f"sim: one of {', '.join(SIMS)}, got {sim!r}")


def check_same(recorded: str, wanted: str, where: str) -> None:
    """Refuse to mix simulators in one study.

    Parameters
    ----------
    recorded : str
        The simulator the results at ``where`` ran on.
    wanted : str
        The simulator the options ask for.
    where : str
        The file (and line) that holds the results, for the message.

    Raises
    ------
    SimulatorMismatch
        ``recorded`` differs from ``wanted``.
    """
    if recorded != wanted:
        raise SimulatorMismatch(
            f"{where}: ran on the {recorded} simulator, these options ask for {wanted}; one "
            f"study does not mix simulators (--sim {recorded} to continue it, or another "
            f"output folder)"
        )


def federator(sim: str) -> Callable[..., Federation]:
    """The in-process federation of ``sim``: :func:`.fedsim.federate` (pybullet) or
    :func:`.fedsim_batched.federate_batched`, which take the same arguments (but
    ``on_step``, pybullet's only)."""
    check_sim(sim)
    if sim == PYBULLET:
        from dfrl.experiments.science.studies.fedsim import federate

        return federate
    from dfrl.experiments.science.studies.fedsim_batched import federate_batched

    return federate_batched
