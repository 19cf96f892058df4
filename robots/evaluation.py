"""Evaluation of a fixed policy: a performance measure that tells driving from spinning.

:func:`evaluate_policy` runs a policy without learning and reports, besides the reward,

* ``collisions_per_1000``: collisions per 1,000 control steps;
* ``progress``: the mean forward progress per step, as a fraction of the top speed
  (``info["progress"]`` clipped to ``[-1, 1]``): 1 drives straight ahead flat out all the time,
  0 spins in place or stands still;
* ``coverage``: the share of the arena's free floor cells (5 cm grid, cells whose centre a robot
  can occupy) that the robot's centre visited in an episode, averaged over the episodes: a
  policy that drives around a small circle covers little.

A policy that spins in place scores ``collisions_per_1000 = 0`` like a perfect one, but its
progress and coverage are near 0; that is why the measure has three numbers. Policies are the
greedy policy of a Q-table or of a function learner's parameter vector (``linear``, ``dqn``:
:func:`greedy_policy`), uniform random actions, or any callable ``obs -> action``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from typing import Any

import numpy as np

from dfrl.robots.approx import FunctionLearner
from dfrl.robots.learners import greedy_action, is_tabular
from dfrl.robots.state import Discretiser
from dfrl.robots.training import TrainerConfig, build_learner

#: Side of the coverage grid's cells (m).
COVERAGE_CELL: float = 0.05


class PolicyKind(str, Enum):
    """Policies that can be evaluated by name."""

    GREEDY = "greedy"  #: argmax of the Q-table (ties at random) or of the model, no learning
    RANDOM = "random"  #: uniform random actions


Policy = Callable[[np.ndarray], int]
"""A hand-made policy: IR proximities, shape (n_sensors,), in [0, 1] -> action index."""


@dataclass(frozen=True)
class EvalResult:
    """Outcome of :func:`evaluate_policy`.

    Attributes
    ----------
    policy : str
    steps : int
    collisions : int
    collisions_per_1000 : float
    distance : float
        Path length driven (m).
    mean_reward : float
    progress : float
        Mean forward progress per step, fraction of top speed, in [-1, 1].
    coverage : float
        Share of the free floor's cells visited per episode (mean over episodes), in [0, 1].
    episodes : int
        Start poses used (one per episode; collisions respawn within an episode).
    """

    policy: str
    steps: int
    collisions: int
    collisions_per_1000: float
    distance: float
    mean_reward: float
    progress: float = 0.0
    coverage: float = 0.0
    episodes: int = 1


def greedy_policy(
    config: TrainerConfig, params: np.ndarray, obs_dim: int = 8, n_actions: int | None = None
) -> Policy:
    """The greedy policy of a function learner (``config.algo``) with parameters ``params``.

    Parameters
    ----------
    config : TrainerConfig
        ``algo`` and the learner's own configuration (``features``, ``dqn``).
    params : np.ndarray, shape (n_params,)
        As :attr:`dfrl.robots.training.Trainer.params`.
    obs_dim : int
    n_actions : int, optional
        Default: the size of ``config.actions``.

    Raises
    ------
    ValueError
        ``config.algo`` is tabular, or ``params`` does not fit the learner.
    """
    if is_tabular(config.algo):
        raise ValueError(f"'{config.algo}' is a tabular learner: evaluate its Q-table")
    n = len(config.actions.names) if n_actions is None else n_actions
    learner = build_learner(config, 1, obs_dim, n, np.random.default_rng(0))
    learner.set_params(params)

    assert isinstance(learner, FunctionLearner), learner  # tabular ones refused above

    def greedy(obs: np.ndarray) -> int:
        return learner.greedy_action(np.asarray(obs, dtype=np.float64))

    return greedy


class _Coverage:
    """Visited cells of a grid over the free floor."""

    def __init__(self, arena, clearance: float) -> None:  # noqa: ANN001 - ArenaSpec
        w, d = arena.size
        self.nx = max(1, int(round(w / COVERAGE_CELL)))
        self.ny = max(1, int(round(d / COVERAGE_CELL)))
        self.x0, self.y0 = -w / 2, -d / 2
        xs = self.x0 + (np.arange(self.nx) + 0.5) * (w / self.nx)
        ys = self.y0 + (np.arange(self.ny) + 0.5) * (d / self.ny)
        gx, gy = np.meshgrid(xs, ys, indexing="ij")
        centres = np.stack([gx.ravel(), gy.ravel()], axis=1)
        self.free = (arena.clearance(centres) >= clearance).reshape(self.nx, self.ny)
        self.seen = np.zeros_like(self.free)
        self.cw, self.cd = w / self.nx, d / self.ny

    def visit(self, x: float, y: float) -> None:
        i = min(self.nx - 1, max(0, int((x - self.x0) / self.cw)))
        j = min(self.ny - 1, max(0, int((y - self.y0) / self.cd)))
        self.seen[i, j] = True

    def share(self) -> float:
        """Share of free cells seen since the last :meth:`restart`."""
        total = int(self.free.sum())
        return float((self.seen & self.free).sum()) / total if total else 0.0

    def restart(self) -> float:
        """Forget the visited cells; return the share seen until now."""
        share = self.share()
        self.seen[:] = False
        return share


def evaluate_policy(
    config: TrainerConfig,
    policy: PolicyKind | str | Policy,
    steps: int,
    seed: int,
    q_table: np.ndarray | None = None,
    episode_steps: int | None = None,
    params: np.ndarray | None = None,
) -> EvalResult:
    """Run a fixed policy in the configured arena and measure it (see the module doc).

    Collisions and respawns follow the training rules (a collision respawns the robot at a
    random free pose; so does being stuck).

    Parameters
    ----------
    config : TrainerConfig
        Arena, simulation, actions, reward and discretisation; with ``params``, also the
        learner (``algo`` and its own configuration).
    policy : PolicyKind, its name, or a callable ``obs -> action``
    steps : int
        Control steps to run in all.
    seed : int
        Seeds the start/respawn poses and the random choices.
    q_table : np.ndarray, shape (n_states, n_actions), optional
        GREEDY of a tabular learner needs it.
    episode_steps : int, optional
        Start a new episode from a fresh random pose every so many steps (many short
        episodes compare policies with fewer steps than one long run). Default: one episode.
    params : np.ndarray, shape (n_params,), optional
        GREEDY of a function learner (``config.algo`` ``linear`` or ``dqn``) needs its
        parameter vector instead of a table (:func:`greedy_policy`).
    """
    from dfrl.robots.env import EPuckEnv

    if callable(policy):
        name, fn, kind = getattr(policy, "__name__", "custom"), policy, None
    else:
        kind = PolicyKind(policy)
        name, fn = kind.value, None
    if episode_steps is not None and episode_steps < 1:
        raise ValueError("episode_steps must be >= 1")
    disc = Discretiser(config.discretisation)
    rng = np.random.default_rng([seed, 7])
    env = EPuckEnv(arena=config.arena, config=config.env_config())
    try:
        n_actions = int(env.action_space.n)
        if kind is PolicyKind.GREEDY and q_table is None and params is not None:
            fn = greedy_policy(config, params, int(env.observation_space.shape[0]), n_actions)
        elif kind is PolicyKind.GREEDY:
            if q_table is None:
                raise ValueError(
                    "a greedy evaluation needs a Q-table (tabular learners) or "
                    "params (function learners)"
                )
            if q_table.shape != (disc.n_states, n_actions):
                raise ValueError(
                    f"Q-table shape {q_table.shape} does not fit the configuration "
                    f"({disc.n_states}, {n_actions})"
                )
        cover = _Coverage(env.arena, env.robot.config.body_radius)
        obs, info = env.reset(seed=seed, options={"random": True})
        # a random start so that evaluation seeds differ even in arenas with a fixed start
        obs, info = env.reset()
        collisions, distance, total, progress, episodes, covered = 0, 0.0, 0.0, 0.0, 1, 0.0
        x, y, _ = info["pose"]
        cover.visit(x, y)
        for k in range(steps):
            if episode_steps is not None and k > 0 and k % episode_steps == 0:
                obs, info = env.reset()
                x, y, _ = info["pose"]
                episodes += 1
                covered += cover.restart()
                cover.visit(x, y)
            if fn is not None:
                action = int(fn(obs))
            elif kind is PolicyKind.GREEDY:
                assert q_table is not None  # checked above: no policy, so a table
                action = greedy_action(q_table[disc(obs)], rng)
            else:
                action = int(rng.integers(n_actions))
            obs, reward, terminated, truncated, info = env.step(action)
            total += reward
            progress += min(max(float(info["progress"]), -1.0), 1.0)
            collisions += bool(info["collision"])
            nx, ny, _ = info["pose"]
            distance += float(np.hypot(nx - x, ny - y))
            x, y = nx, ny
            cover.visit(x, y)
            if terminated or truncated:
                obs, info = env.reset()
                x, y, _ = info["pose"]
        n = max(steps, 1)
        return EvalResult(
            policy=name,
            steps=steps,
            collisions=collisions,
            collisions_per_1000=1000.0 * collisions / n,
            distance=distance,
            mean_reward=total / n,
            progress=progress / n,
            coverage=(covered + cover.share()) / episodes,
            episodes=episodes,
        )
    finally:
        env.close()


#: Columns of :func:`evaluate_snapshots` rows (``evaluations.csv``).
EVAL_FIELDS: tuple[str, ...] = (
    "iteration",
    "arena",
    "steps",
    "collisions_per_1000",
    "progress",
    "coverage",
    "mean_reward",
)


def evaluate_snapshots(
    config: TrainerConfig,
    snapshots: dict[int, np.ndarray],
    arenas: list[str] | tuple[str, ...],
    steps: int,
    seed: int,
    episode_steps: int = 250,
) -> list[dict[str, float | int | str]]:
    """The greedy policy of every snapshot, measured in each of ``arenas``.

    The same evaluation seed is used for every snapshot and arena (the start poses are the
    same across snapshots, so the curves compare tables, not luck).

    Parameters
    ----------
    config : TrainerConfig
        Simulation, actions, reward and discretisation of the tables (its arena is replaced).
    snapshots : dict of int to np.ndarray
        Iteration -> Q-table, as :func:`dfrl.robots.training.train` keeps them.
    arenas : sequence of str
        Where to evaluate (e.g. the own arena plus :data:`dfrl.arenas.HELD_OUT_ARENAS`).
    steps, seed, episode_steps
        As in :func:`evaluate_policy`.

    Returns
    -------
    list of dict
        One row per (iteration, arena) with the columns :data:`EVAL_FIELDS`.
    """
    rows: list[dict[str, float | int | str]] = []
    for iteration in sorted(snapshots):
        for arena in arenas:
            r = evaluate_policy(
                config.replace(arena=arena),
                PolicyKind.GREEDY,
                steps,
                seed,
                q_table=snapshots[iteration],
                episode_steps=episode_steps,
            )
            rows.append(
                {
                    "iteration": iteration,
                    "arena": arena,
                    "steps": r.steps,
                    "collisions_per_1000": r.collisions_per_1000,
                    "progress": r.progress,
                    "coverage": r.coverage,
                    "mean_reward": r.mean_reward,
                }
            )
    return rows


def learnt_vs_random(
    config: TrainerConfig, seed: int, steps: int, eval_seed: int, params: np.ndarray | None = None
) -> dict[str, Any]:
    """Train ``config`` with ``seed`` (unless ``params`` are given), then measure its greedy
    policy and a uniform random one from the same start and respawn poses.

    Works for every learner (a table or a parameter vector); the row has the shape of
    ``dfrl eval``'s per-seed rows: ``seed``, ``train_s``, ``greedy`` and ``random`` (the
    :class:`EvalResult` fields).

    Parameters
    ----------
    config : TrainerConfig
    seed : int
        Training seed.
    steps : int
        Evaluation steps per policy.
    eval_seed : int
    params : np.ndarray, optional
        A function learner's parameters to evaluate instead of training.
    """
    import time

    from dfrl.robots.training import train

    cfg = config.replace(seed=seed)
    t0 = time.perf_counter()
    if params is None:
        res = train(cfg)
        table, params = res.q_table, (None if res.q_table is not None else res.params)
    else:
        table = None
    train_s = time.perf_counter() - t0
    greedy = evaluate_policy(cfg, PolicyKind.GREEDY, steps, eval_seed, q_table=table, params=params)
    rand = evaluate_policy(cfg, PolicyKind.RANDOM, steps, eval_seed)
    return {
        "seed": seed,
        "train_s": round(train_s, 2),
        "greedy": greedy.__dict__,
        "random": rand.__dict__,
    }
