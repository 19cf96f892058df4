"""Reference Q-tables of an arena and the error of a robot's table against one.

A measure with resolution beside the greedy score (issue 18): the greedy score of a table
jumps between evaluations, the distance of the table to a reference table of its arena moves
with every update.

**How a reference is made** (:func:`build_reference`). ``K`` standalone runs of
``iterations`` steps each, the same :class:`~dfrl.robots.training.TrainerConfig` apart from
the seed, through :func:`dfrl.robots.training.train`. For every state-action pair:

* ``q[s, a]`` is the mean of ``Q_k[s, a]`` over the runs ``k`` that updated the pair at least
  once (a run that never did still holds the initial value, which would pull the mean towards
  it); a pair no run updated keeps the learner's initial value;
* ``visits[s, a]`` is the number of updates summed over the runs;
* ``runs[s, a]`` is the number of runs that updated it.

The build also records the reference's own spread: ``seed_rms``, the mean over the runs of
the error (:func:`table_error`, RMS) of each run's table against the reference. It is the
error a single run of the reference's length reaches, a floor below which smaller errors of
shorter runs mean nothing (it underestimates the spread slightly: each run is part of the
mean it is compared with).

**The cache** (:func:`reference_table`). A reference is stored in a folder (default
:func:`default_cache`: ``$DFRL_REFERENCE_CACHE``, else ``$XDG_CACHE_HOME/dfrl/references``,
else ``~/.cache/dfrl/references``) as three files named after the recipe,
``<arena>-<algo>-<iterations>x<K>-<key>``, where ``key`` is the first 12 hex digits of the
sha256 of the recipe's canonical JSON (the whole training configuration and the seeds; not the
dfrl version, which is recorded but does not change the name):

* ``NAME.q.npy``: float64 ``(n_states, n_actions)``;
* ``NAME.visits.npy``: int64 ``(2, n_states, n_actions)``: the summed visits, then the runs;
* ``NAME.json``: the sidecar, format ``dfrl-reference/1``: ``recipe`` (arena, algo,
  iterations, seeds, the base training configuration, ``min_visits``), ``built`` (dfrl
  version, git commit and whether the checkout had changes, the full provenance of
  :mod:`dfrl.experiments.provenance`, build seconds, ``seed_rms``) and ``sha256``: the
  checksum of each ``.npy`` file's bytes (``sha256sum NAME.q.npy`` gives the same digest).

References shipped with the code live in ``experiments/science/references/`` (:data:`SHIPPED`,
read only): :func:`reference_table` looks there when the cache has none. Shipped:
``r1-qlearning-50000x5-98d163de57bb`` (R1, Q-learning, the default configuration, 50,000
iterations x seeds 1-5; 8 KB). A shipped reference is stale when the simulation or the learner
changes without changing the configuration: the slow test
``test_shipped_reference_rebuilds_bit_for_bit`` rebuilds it and compares the checksums.

Loading verifies both checksums and the recipe; a mismatch raises :class:`ReferenceError`
naming the file. Whatever goes wrong, nothing is silently rebuilt over a corrupted file.

**The distance** (:func:`table_error`): over the pairs the reference updated at least
``min_visits`` times (summed over its runs),

* ``rms``: the root mean square of ``table - reference``;
* ``relative``: ``rms`` divided by the RMS of the reference itself over the same pairs, so the
  table of the initial value 0 is at exactly 1 (learnt tables in R1: 0.87 after 1,000
  iterations, 0.65 after 16,000, science/README.md);
* ``disagreement``: over the states whose every action the reference updated ``min_visits``
  times, the mean probability that the table's greedy action (ties broken uniformly, as the
  learners do) is not one of the reference's greedy actions.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dfrl.experiments.errors import ExperimentError

#: Sidecar format of a stored reference.
REFERENCE_FORMAT = "dfrl-reference/1"
#: Pairs the reference updated fewer times than this (summed over its runs) are left out of
#: the distance: their reference value is itself a guess.
DEFAULT_MIN_VISITS = 10
#: ``dfrl reference`` defaults: long runs over several seeds.
DEFAULT_ITERATIONS = 50_000
DEFAULT_SEEDS = 5
#: References shipped with the code (read only; looked up after the cache).
SHIPPED = Path(__file__).resolve().parent / "references"


class ReferenceError(ExperimentError):
    """A stored reference is missing a file, fails its checksum, or is not what was asked."""


@dataclass(frozen=True)
class Reference:
    """A reference table of an arena.

    Attributes
    ----------
    q : np.ndarray, float64, shape (n_states, n_actions)
    visits : np.ndarray, int64, shape (n_states, n_actions)
        Updates of each pair, summed over the runs.
    runs : np.ndarray, int64, shape (n_states, n_actions)
        Runs that updated each pair at least once.
    recipe : dict
        What was trained (:func:`reference_recipe`).
    built : dict
        dfrl version, git state, provenance, build seconds, ``seed_rms``.
    path : Path or None
        The sidecar it was loaded from or saved to.
    """

    q: np.ndarray
    visits: np.ndarray
    runs: np.ndarray
    recipe: dict[str, Any]
    built: dict[str, Any]
    path: Path | None = None

    @property
    def name(self) -> str:
        """The file stem the cache stores it under."""
        return reference_name(self.recipe)


@dataclass(frozen=True)
class TableError:
    """The distance of a table to a reference (:func:`table_error`).

    Attributes
    ----------
    rms : float
        Root mean square difference over the ``pairs`` counted (NaN when none).
    relative : float
        ``rms`` over the reference's own RMS on those pairs (NaN when that is 0).
    disagreement : float
        Mean probability over the ``states`` counted that the table's greedy action is not a
        greedy action of the reference (NaN when none).
    pairs : int
        State-action pairs counted in ``rms``.
    states : int
        States counted in ``disagreement``.
    """

    rms: float
    relative: float
    disagreement: float
    pairs: int
    states: int


# -- the distance ------------------------------------------------------------------------------
def _greedy_sets(q: np.ndarray) -> np.ndarray:
    """Boolean ``(n_states, n_actions)``: the actions of highest value in each row."""
    return q == q.max(axis=1, keepdims=True)


def table_error(
    table: np.ndarray,
    reference: Reference | np.ndarray,
    visits: np.ndarray | None = None,
    min_visits: int = DEFAULT_MIN_VISITS,
) -> TableError:
    """The distance of ``table`` to ``reference`` (module docstring, "The distance").

    Parameters
    ----------
    table : np.ndarray, shape (n_states, n_actions)
    reference : Reference or np.ndarray of the same shape
    visits : np.ndarray of the same shape, optional
        The reference's visit counts; default ``reference.visits`` for a :class:`Reference`,
        and every pair counted for a bare array.
    min_visits : int
        Pairs with fewer visits are left out.

    Raises
    ------
    ValueError
        Shapes differ, a value is not finite, visits are negative or ``min_visits < 0``.
    """
    ref_q = reference.q if isinstance(reference, Reference) else np.asarray(reference)
    if visits is None and isinstance(reference, Reference):
        visits = reference.visits
    q = np.asarray(table, dtype=np.float64)
    ref_q = np.asarray(ref_q, dtype=np.float64)
    if q.ndim != 2 or q.shape != ref_q.shape:
        raise ValueError(f"table shape {q.shape} differs from the reference's {ref_q.shape}")
    if not (np.isfinite(q).all() and np.isfinite(ref_q).all()):
        raise ValueError("tables must be finite")
    if min_visits < 0:
        raise ValueError(f"min_visits must be >= 0, got {min_visits}")
    if visits is None:
        counted = np.ones(q.shape, dtype=bool)
    else:
        v = np.asarray(visits)
        if v.shape != q.shape:
            raise ValueError(f"visits shape {v.shape} differs from the table's {q.shape}")
        if (v < 0).any():
            raise ValueError("visits must be >= 0")
        counted = v >= min_visits
    pairs = int(counted.sum())
    if pairs:
        diff = q[counted] - ref_q[counted]
        rms = float(np.sqrt(np.mean(diff * diff)))
        scale = float(np.sqrt(np.mean(ref_q[counted] ** 2)))
        relative = rms / scale if scale > 0 else float("nan")
    else:
        rms = relative = float("nan")
    states = counted.all(axis=1)
    n_states = int(states.sum())
    if n_states:
        mine, best = _greedy_sets(q[states]), _greedy_sets(ref_q[states])
        agree = (mine & best).sum(axis=1) / mine.sum(axis=1)
        disagreement = float(np.mean(1.0 - agree))
    else:
        disagreement = float("nan")
    return TableError(
        rms=rms, relative=relative, disagreement=disagreement, pairs=pairs, states=n_states
    )


# -- recipes and names -------------------------------------------------------------------------
def reference_recipe(
    arena: str,
    algo: str,
    iterations: int,
    seeds: Sequence[int],
    base: Any = None,
    min_visits: int = DEFAULT_MIN_VISITS,
) -> dict[str, Any]:
    """What a reference is trained from: JSON-ready, the input of its name and key.

    Parameters
    ----------
    arena, algo : str
    iterations : int
        Steps per run (>= 1).
    seeds : sequence of int
        One run per seed (at least one, no repeats); recorded sorted, so the order given
        does not change the reference or its name.
    base : TrainerConfig, optional
        Every other training setting (default: the defaults); its arena, algo, seed and
        iterations are replaced.
    min_visits : int
        Recorded for :func:`table_error` users; ``seed_rms`` is computed with it.

    Raises
    ------
    ValueError
        No seeds, a repeated seed, ``iterations < 1``, or a learner without a Q-table.
    """
    from dfrl.robots.learners import learner_kind
    from dfrl.robots.training import TrainerConfig

    if iterations < 1:
        raise ValueError(f"iterations must be >= 1, got {iterations}")
    seeds = sorted(int(s) for s in seeds)
    if not seeds or len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds must be distinct and at least one, got {seeds}")
    if learner_kind(algo) != "tabular":
        raise ValueError(f"a reference table needs a tabular learner, not {algo!r}")
    cfg = (base or TrainerConfig()).replace(
        arena=str(arena), algo=algo, seed=0, iterations=int(iterations)
    )
    return {
        "arena": str(arena),
        "algo": algo,
        "iterations": int(iterations),
        "seeds": seeds,
        "min_visits": int(min_visits),
        "config": cfg.to_dict(),
    }


def recipe_key(recipe: dict[str, Any]) -> str:
    """sha256 of the recipe's canonical JSON (sorted keys, no spaces), 64 hex digits."""
    text = json.dumps(recipe, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def reference_name(recipe: dict[str, Any]) -> str:
    """``<arena>-<algo>-<iterations>x<K>-<key12>``; an arena file contributes its stem."""
    arena = re.sub(r"[^A-Za-z0-9_]+", "_", Path(recipe["arena"]).stem) or "arena"
    return (
        f"{arena}-{recipe['algo']}-{recipe['iterations']}x{len(recipe['seeds'])}-"
        f"{recipe_key(recipe)[:12]}"
    )


def default_cache() -> Path:
    """``$DFRL_REFERENCE_CACHE``, else ``$XDG_CACHE_HOME/dfrl/references``, else
    ``~/.cache/dfrl/references`` (a getter: nothing is created)."""
    if os.environ.get("DFRL_REFERENCE_CACHE"):
        return Path(os.environ["DFRL_REFERENCE_CACHE"])
    root = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(root) / "dfrl" / "references"


# -- building ----------------------------------------------------------------------------------
def _run(cfg_dict: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    """One standalone run (a process-pool job): its final table and visits."""
    from dfrl.robots.training import TrainerConfig, train

    result = train(TrainerConfig.from_dict(cfg_dict))
    assert result.q_table is not None and result.visits is not None
    return result.q_table, result.visits


def combine(
    tables: Sequence[np.ndarray], visits: Sequence[np.ndarray], initial_q: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The reference of some runs' tables (module docstring): ``(q, visits, runs)``.

    Parameters
    ----------
    tables, visits : sequences of np.ndarray, shape (n_states, n_actions), same length
    initial_q : float
        The value of pairs no run updated.
    """
    if not tables or len(tables) != len(visits):
        raise ValueError("need as many visit arrays as tables, at least one")
    q = np.stack([np.asarray(t, dtype=np.float64) for t in tables])
    v = np.stack([np.asarray(x, dtype=np.int64) for x in visits])
    if q.shape != v.shape:
        raise ValueError(f"tables {q.shape[1:]} and visits {v.shape[1:]} differ in shape")
    updated = v > 0
    runs = updated.sum(axis=0)
    total = np.where(updated, q, 0.0).sum(axis=0)
    mean = np.where(runs > 0, total / np.maximum(runs, 1), float(initial_q))
    return mean, v.sum(axis=0), runs.astype(np.int64)


def build_reference(recipe: dict[str, Any], jobs: int = 1) -> Reference:
    """Train the recipe's runs (``jobs`` processes) and combine them; nothing is stored."""
    from dfrl.robots.training import TrainerConfig

    base = TrainerConfig.from_dict(recipe["config"])
    cfgs = [base.replace(seed=s).to_dict() for s in recipe["seeds"]]
    t0 = time.perf_counter()
    if jobs > 1 and len(cfgs) > 1:
        with ProcessPoolExecutor(max_workers=min(jobs, len(cfgs))) as pool:
            done = list(pool.map(_run, cfgs))
    else:
        done = [_run(c) for c in cfgs]
    seconds = time.perf_counter() - t0
    tables, visits = [d[0] for d in done], [d[1] for d in done]
    q, v, runs = combine(tables, visits, base.learner.initial_q)
    seed_rms = [table_error(t, q, v, recipe["min_visits"]).rms for t in tables]
    from dfrl.experiments.provenance import provenance

    prov = provenance()
    built = {
        "dfrl": prov["dfrl"],
        "git": prov["git"],
        "provenance": prov,
        "seconds": seconds,
        "jobs": jobs,
        "seed_rms": float(np.mean(seed_rms)),
        "seed_rms_per_run": [float(x) for x in seed_rms],
    }
    return Reference(q=q, visits=v, runs=runs, recipe=recipe, built=built)
