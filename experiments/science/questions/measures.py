"""Per-seed values of a condition, from its evaluations (:mod:`.evaluations`).

A condition's value for a seed is the mean, over the arenas its robots learnt in, of the mean
over that arena's robots of the measure at each robot's last evaluated iteration: in the
robot's own arena (``own``) or averaged over the arenas it never learnt in (``held_out``).
Two conditions are compared on the arenas both have (the same arenas, seeds and evaluation
episodes), so a standalone robot of R1 meets the federated robot of R1.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Iterable, Sequence

import numpy as np

from dfrl.experiments.science.questions.evaluations import Evaluation

#: (run, seed, role, measure) -> robot arena -> value.
ByArena = dict[tuple[str, int, str, str], dict[str, float]]


def final_by_arena(evals: Iterable[Evaluation]) -> ByArena:
    """Each condition's final values per seed, role and measure, by the robots' arena."""
    evals = list(evals)
    last: dict[tuple[str, int, str], int] = {}
    for e in evals:
        key = (e.run, e.seed, e.robot)
        last[key] = max(last.get(key, e.iteration), e.iteration)
    per_robot: dict[tuple[str, int, str, str, str, str], list[float]] = defaultdict(list)
    for e in evals:
        if e.iteration != last[(e.run, e.seed, e.robot)]:
            continue
        for m in ("score", "collisions_per_1000"):
            per_robot[(e.run, e.seed, e.role, m, e.robot_arena, e.robot)].append(getattr(e, m))
    per_arena: dict[tuple[str, int, str, str, str], list[float]] = defaultdict(list)
    for (run, seed, role, m, arena, _robot), vals in per_robot.items():
        per_arena[(run, seed, role, m, arena)].append(float(np.mean(vals)))
    out: ByArena = defaultdict(dict)
    for (run, seed, role, m, arena), vals in per_arena.items():
        out[(run, seed, role, m)][arena] = float(np.mean(vals))
    return dict(out)


def runs_of(values: ByArena) -> list[str]:
    """The conditions present, in first-seen order."""
    return list(dict.fromkeys(k[0] for k in values))


def seeds_of(values: ByArena, run: str) -> list[int]:
    return sorted({k[1] for k in values if k[0] == run})


def paired(
    values: ByArena,
    a: str,
    b: str,
    role: str,
    measure: str,
) -> tuple[list[int], list[float], list[float]]:
    """The seeds both conditions have, and each one's value there over their common arenas
    (a seed where they share no arena is left out)."""
    seeds, va, vb = [], [], []
    for s in sorted(set(seeds_of(values, a)) & set(seeds_of(values, b))):
        xa = values.get((a, s, role, measure), {})
        xb = values.get((b, s, role, measure), {})
        common = sorted(set(xa) & set(xb))
        if not common:
            continue
        seeds.append(s)
        va.append(float(np.mean([xa[k] for k in common])))
        vb.append(float(np.mean([xb[k] for k in common])))
    return seeds, va, vb


def arena_matrix(
    values: ByArena,
    run: str,
    role: str = "own",
    measure: str = "score",
    arenas: Sequence[str] | None = None,
) -> np.ndarray:
    """(seeds x arenas) of one condition (rliable's runs x tasks layout); nan where missing."""
    seeds = seeds_of(values, run)
    arenas = (
        list(arenas)
        if arenas is not None
        else sorted({a for k, v in values.items() if k[0] == run and k[2] == role for a in v})
    )
    m = np.full((len(seeds), len(arenas)), np.nan)
    for i, s in enumerate(seeds):
        row = values.get((run, s, role, measure), {})
        for j, a in enumerate(arenas):
            m[i, j] = row.get(a, np.nan)
    return m
