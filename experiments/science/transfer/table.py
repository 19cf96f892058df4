"""The table to transfer and the trainer configuration that fits it."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from dfrl.experiments.science.transfer.model import TableInfo, TransferConfig
from dfrl.robots.env import ActionSet
from dfrl.robots.learners import LEARNERS, validate_table
from dfrl.robots.state import DiscretisationConfig, SensorGrouping
from dfrl.robots.tables import load_table
from dfrl.robots.training import TrainerConfig


def load_initial_table(path: str | Path) -> tuple[np.ndarray, TableInfo, dict[str, Any] | None]:
    """Read the table to transfer, with its sidecar when there is one.

    Returns
    -------
    q : np.ndarray, shape (n_states, n_actions), float64
    info : TableInfo
    state : dict or None
        The sidecar's discretisation description (``None`` for a bare ``.npy``).

    Raises
    ------
    ValueError
        Missing file, unreadable or inconsistent table, non-finite entries.
    """
    p = Path(path)
    npy = p if p.suffix == ".npy" else p.with_name(p.name + ".npy")
    if not npy.exists():
        raise ValueError(f"{npy}: no such table")
    if npy.with_suffix(".json").exists():
        loaded = load_table(npy)
        q, meta = loaded.q, loaded.meta
        info = TableInfo(
            path=str(npy),
            shape=tuple(q.shape),
            algo=meta.algo,
            arena=meta.arena,
            iterations=meta.iterations,
            sidecar=True,
            extra=dict(meta.extra),
        )
        found: dict[str, Any] = dict(meta.state)
        found["actions"] = list(meta.actions)
        return q, info, found
    try:
        raw = np.load(npy, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise ValueError(f"{npy}: not a readable .npy array ({exc})") from None
    if raw.ndim != 2:
        raise ValueError(f"{npy}: a Q-table is 2-D (n_states, n_actions), got shape {raw.shape}")
    q = validate_table(raw, raw.shape)
    info = TableInfo(
        path=str(npy), shape=tuple(q.shape), algo=None, arena=None, iterations=None, sidecar=False
    )
    return q, info, None


def trainer_config_for(
    config: TransferConfig, q: np.ndarray, info: TableInfo, state: dict[str, Any] | None
) -> TrainerConfig:
    """The training configuration of both conditions, checked against the table's shape.

    Algorithm (``info``), sensor grouping, levels and action set (``state``, the sidecar's
    discretisation description plus its ``actions`` names) come from the sidecar unless
    overridden in ``config``; everything else is the :class:`TrainerConfig` default.

    Raises
    ------
    ValueError
        The table's shape does not fit the resulting discretisation and action set, or its
        action names match no :class:`dfrl.robots.env.ActionSet`.
    """
    base = TrainerConfig()
    algo = config.algo or info.algo or base.algo
    if algo not in LEARNERS:
        raise ValueError(f"unknown learner '{algo}'; registered: {sorted(LEARNERS)}")
    grouping = config.grouping or (state or {}).get("grouping") or base.discretisation.grouping
    levels = config.levels or (state or {}).get("levels") or base.discretisation.levels
    disc = DiscretisationConfig(SensorGrouping(grouping), int(levels))
    actions = base.actions
    if state is not None and "actions" in state:
        names = list(state["actions"])
        matches = [a for a in ActionSet if a.names == names]
        if not matches:
            raise ValueError(
                f"{config.init}: action names {names} match no action set "
                f"({', '.join(f'{a.value}: {a.names}' for a in ActionSet)})"
            )
        actions = matches[0]
    expected = (disc.n_states, len(actions.names))
    if tuple(q.shape) != expected:
        src = "its sidecar" if state is not None else "the defaults (no sidecar)"
        raise ValueError(
            f"{config.init}: table shape {tuple(q.shape)} does not fit the trainer: grouping "
            f"'{disc.grouping.value}' x {disc.levels} levels = {disc.n_states} states and "
            f"{len(actions.names)} actions ({actions.value}) need shape {expected} "
            f"(discretisation from {'the overrides' if config.grouping or config.levels else src})"
        )
    return base.replace(
        arena=config.arena,
        iterations=config.iterations,
        algo=algo,
        discretisation=disc,
        actions=actions,
    )
