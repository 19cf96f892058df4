"""Which learning control cannot learn? Candidates measured against the zero table (issue 34).

``dfrl paper`` judges "do robots learn" as a trained table's greedy score minus a *learning
control's*, and minus the untrained all-zero table's, paired by seed. A control must be
behaviourally negative: its contrast against the zero table must include 0. This study trains
each candidate control the way the paper trains its runs (standalone: each arena R1..R5 alone,
arena ``r<k>`` with seed ``s + k - 1`` as the paper's robots; federated: the five robots
averaging every 500 iterations in one process, :func:`dfrl.experiments.science.studies.fedsim.
federate`) and evaluates the final table exactly as the paper does
(:func:`dfrl.experiments.science.studies.history.eval_job`: greedy, 1,000 steps in episodes of
200, own arena and held-out H1 and H2, evaluation seed ``50,000 + s``); the zero table is
evaluated in every arena with the same seed. A seed's contrast is the mean over its robots'
evaluations of (score - zero table's score in that arena), as ``greedy_gain`` computes it.

Candidates (what the learner's update sees instead of the observed reward r and end flag); the
first three are the modes of ``reward_shuffle_mode`` (:mod:`dfrl.robots.reward_shuffle`; the
classes here give bitwise the same tables as the library's modes):

``shuffle``
    ``raw``, the control before issue 34: (r, end) drawn from a seeded buffer of the last
    1,000 observed outcomes, uncentred.
``centred``
    The same draw, its reward minus the mean reward of the buffer it was drawn from; the end
    flag travels with it.
``no_bootstrap``
    ``centred_no_bootstrap``, the default since issue 34: ``centred`` with every update
    terminal (no bootstrap on the real next state).
``permuted``
    A fixed seeded permutation of the (state, action) pairs: the update of (s, a) learns the
    outcome last observed at the pair the permutation maps (s, a) to (a buffer draw until that
    pair has been seen), its reward centred by the buffer's mean: a consistent but relabelled
    reward function (not measured in issue 34, for want of compute).
``library``
    The trainer's own default control (``reward_shuffle=1000``).
``random_table``
    No training: a table of seeded standard normal values (a fixed policy that knows nothing;
    federated, one table for the five robots).
``trained``
    The ordinary learner (for scale).

Usage (bounded: every run is 15,000 iterations by default)::

    python -m dfrl.experiments.tools.control_study run OUT --candidates shuffle centred \\
        --algos qlearning sarsa --seeds 1 2 3 4 5 --jobs 2
    python -m dfrl.experiments.tools.control_study summary OUT

``run`` appends one JSON line per evaluation to ``OUT/rows.jsonl`` and skips what is there;
``summary`` prints the table. This tool imports the science studies it measures with
(``history``, ``fedsim``): it is a measurement, not part of any run.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from dfrl.experiments.science.statistics import interval
from dfrl.experiments.science.studies import fedsim, history
from dfrl.robots.state import Discretiser
from dfrl.robots.training import Trainer, TrainerConfig

ARENAS = ("r1", "r2", "r3", "r4", "r5")
HELD_OUT = ("h1", "h2")
EVAL_SEED = 50_000
EVAL_STEPS, EPISODE_STEPS = 1000, 200
BUFFER = 1000
RESPITE = 500
ROWS = "rows.jsonl"

Outcome = Callable[[float, bool], tuple[float, bool]]


class CentredShuffle:
    """``RewardShuffle``'s draw, its reward minus the mean of the rewards it was drawn from."""

    def __init__(self, capacity: int, rng: np.random.Generator, always_end: bool = False) -> None:
        self.capacity, self._rng, self.always_end = capacity, rng, always_end
        self.r: list[float] = []
        self.end: list[bool] = []
        self._sum = 0.0
        self._n = 0

    def draw(self, reward: float, terminal: bool) -> tuple[float, bool]:
        """(drawn reward - mean of the buffer drawn from, drawn end flag)."""
        self._n += 1
        if self._n % self.capacity == 0:
            self._sum = float(np.sum(self.r))  # no drift of the running sum
        if len(self.r) < self.capacity:
            self.r.append(float(reward))
            self.end.append(bool(terminal))
            self._sum += float(reward)
            j = int(self._rng.integers(len(self.r)))
            return self.r[j] - self._sum / len(self.r), self.end[j]
        j = int(self._rng.integers(self.capacity))
        out = (self.r[j] - self._sum / self.capacity, self.end[j])
        self._sum += float(reward) - self.r[j]
        self.r[j], self.end[j] = float(reward), bool(terminal)
        return out

    def __call__(self, reward: float, terminal: bool) -> tuple[float, bool]:
        r, end = self.draw(reward, terminal)
        return r, (True if self.always_end else end)


class PermutedPairs:
    """The outcome last observed at ``perm[(s, a)]``, centred by a shuffle buffer's mean."""

    def __init__(self, trainer: Trainer, rng: np.random.Generator) -> None:
        self.t = trainer
        n = trainer.n_states * len(trainer.action_names)
        self.n_actions = len(trainer.action_names)
        self.perm = rng.permutation(n)
        self.last_r = np.full(n, np.nan)
        self.last_end = np.zeros(n, dtype=bool)
        self.buffer = CentredShuffle(BUFFER, rng)

    def __call__(self, reward: float, terminal: bool) -> tuple[float, bool]:
        k = self.t._state * self.n_actions + self.t._action  # the pair being updated
        drawn = self.buffer(reward, terminal)  # keeps the buffer and its mean
        mean = self.buffer._sum / len(self.buffer.r)
        self.last_r[k], self.last_end[k] = reward, terminal
        src = self.perm[k]
        if np.isnan(self.last_r[src]):
            return drawn
        return float(self.last_r[src]) - mean, bool(self.last_end[src])


def _shuffle_rng(seed: int) -> np.random.Generator:
    """The trainer's third stream (the one ``reward_shuffle`` uses)."""
    return np.random.default_rng(np.random.SeedSequence(seed).spawn(3)[2])


def make_trainer(candidate: str, cfg: TrainerConfig) -> Trainer:
    """A trainer whose update sees ``candidate``'s outcomes."""
    if candidate == "shuffle":
        return Trainer(cfg.replace(reward_shuffle=BUFFER, reward_shuffle_mode="raw"))
    t = Trainer(cfg)
    rng = _shuffle_rng(cfg.seed)
    if candidate == "centred":
        t.reward_shuffle = CentredShuffle(BUFFER, rng)  # type: ignore[assignment]
    elif candidate == "no_bootstrap":
        t.reward_shuffle = CentredShuffle(BUFFER, rng, always_end=True)  # type: ignore[assignment]
    elif candidate == "permuted":
        t.reward_shuffle = PermutedPairs(t, rng)  # type: ignore[assignment]
    elif candidate == "library":
        t.close()
        return Trainer(cfg.replace(reward_shuffle=BUFFER))
    elif candidate != "trained":
        t.close()
        raise ValueError(f"unknown candidate {candidate!r}")
    return t


def _describe(q: np.ndarray, visits: np.ndarray | None) -> dict[str, Any]:
    """Greedy action in the open-floor state (0) and the visit-weighted forward share."""
    greedy = np.argmax(q, axis=1)
    out: dict[str, Any] = {"greedy0": int(greedy[0]), "q0": [round(float(v), 3) for v in q[0]]}
    if visits is not None:
        w = visits.sum(axis=1)
        out["fwd_share"] = round(float(w[greedy == 0].sum() / max(1, w.sum())), 3)
    return out


def _random_table(seed: int, k: int) -> np.ndarray:
    """Seeded standard normal values, the shape of the default table (k: the robot, 5: the
    federation's one table)."""
    cfg = TrainerConfig()
    return np.random.default_rng([seed, k, 34]).standard_normal(
        (Discretiser(cfg.discretisation).n_states, len(cfg.actions.names))
    )


def standalone_job(
    candidate: str, algo: str, arena: str, seed: int, iterations: int
) -> list[dict[str, Any]]:
    """Train one robot (the paper's seed for ``arena``) and evaluate its final table."""
    k = ARENAS.index(arena)
    cfg = TrainerConfig(arena=arena, algo=algo, seed=seed + k, iterations=iterations)
    t0 = time.process_time()
    if candidate == "random_table":
        q, visits = _random_table(seed, k), None
    else:
        with make_trainer(candidate, cfg) as t:
            for _ in range(iterations):
                t.step()
            q, visits = t.q_table.copy(), t.visits.copy()
    base = {
        "candidate": candidate,
        "algo": algo,
        "mode": "standalone",
        "seed": seed,
        "robot": arena,
        "train_cpu": round(time.process_time() - t0, 2),
        **_describe(q, visits),
    }
    return [
        {
            **base,
            "arena": a,
            "role": "own" if a == arena else "held_out",
            **history.eval_job(
                TrainerConfig().to_dict(), q, a, EVAL_STEPS, EPISODE_STEPS, EVAL_SEED + seed
            ),
        }
        for a in (arena,) + HELD_OUT
    ]


def federated_job(candidate: str, algo: str, seed: int, iterations: int) -> list[dict[str, Any]]:
    """Five robots R1..R5 averaging every 500 iterations; the shared final table evaluated in
    every robot's arena and the held-out ones (identical tables: once per arena)."""
    cfgs = [
        TrainerConfig(arena=a, algo=algo, seed=seed + k, iterations=iterations)
        for k, a in enumerate(ARENAS)
    ]
    t0 = time.process_time()
    if candidate == "random_table":  # one table of random numbers for all five robots
        table, visits = _random_table(seed, 5), None
    else:
        original = fedsim.Trainer
        fedsim.Trainer = lambda c: make_trainer(candidate, c)  # type: ignore[assignment,misc]
        try:
            fed = fedsim.federate(cfgs, iterations, RESPITE, "average")
        finally:
            fedsim.Trainer = original  # type: ignore[misc]
        table, visits = fed.table, fed.visits
    base = {
        "candidate": candidate,
        "algo": algo,
        "mode": "federated",
        "seed": seed,
        "train_cpu": round(time.process_time() - t0, 2),
        **_describe(table, visits),
    }
    scores = {
        a: history.eval_job(
            TrainerConfig().to_dict(), table, a, EVAL_STEPS, EPISODE_STEPS, EVAL_SEED + seed
        )
        for a in ARENAS + HELD_OUT
    }
    rows = []
    for robot in ARENAS:  # one row per robot and arena, as the paper's evaluations
        for a in (robot,) + HELD_OUT:
            rows.append(
                {
                    **base,
                    "robot": robot,
                    "arena": a,
                    "role": "own" if a == robot else "held_out",
                    **scores[a],
                }
            )
    return rows


def zero_job(seed: int) -> list[dict[str, Any]]:
    """The all-zero table in every arena with the seed's evaluation seed."""
    cfg = TrainerConfig()
    q = np.zeros((Discretiser(cfg.discretisation).n_states, len(cfg.actions.names)))
    return [
        {
            "candidate": "zero",
            "seed": seed,
            "arena": a,
            **history.eval_job(cfg.to_dict(), q, a, EVAL_STEPS, EPISODE_STEPS, EVAL_SEED + seed),
        }
        for a in ARENAS + HELD_OUT
    ]


def read_rows(out: Path) -> list[dict[str, Any]]:
    f = out / ROWS
    return [json.loads(line) for line in f.read_text().splitlines() if line] if f.exists() else []


def _key(r: dict[str, Any]) -> tuple:
    return (
        r["candidate"],
        r.get("algo"),
        r.get("mode"),
        r["seed"],
        r.get("robot") if r.get("mode") == "standalone" else None,
    )


def run(
    out: Path,
    candidates: Iterable[str],
    algos: Iterable[str],
    seeds: list[int],
    modes: Iterable[str],
    iterations: int,
    jobs: int,
) -> None:
    """Every missing job on ``jobs`` processes, rows appended as they finish."""
    out.mkdir(parents=True, exist_ok=True)
    done = {_key(r) for r in read_rows(out)}
    todo: list[tuple[Callable[..., list[dict[str, Any]]], tuple]] = []
    for s in seeds:
        if ("zero", None, None, s, None) not in done:
            todo.append((zero_job, (s,)))
    for c in candidates:
        for algo in algos:
            for mode in modes:
                for s in seeds:
                    if mode == "federated":
                        if (c, algo, mode, s, None) not in done:
                            todo.append((federated_job, (c, algo, s, iterations)))
                    else:
                        for a in ARENAS:
                            if (c, algo, mode, s, a) not in done:
                                todo.append((standalone_job, (c, algo, a, s, iterations)))
    t0 = time.monotonic()
    with ProcessPoolExecutor(max_workers=max(1, jobs)) as pool, (out / ROWS).open("a") as f:
        futs = [pool.submit(fn, *args) for fn, args in todo]
        for i, fut in enumerate(futs):
            rows = fut.result()
            for r in rows:
                f.write(json.dumps(r) + "\n")
            f.flush()
            print(
                f"[{i + 1}/{len(futs)}] {time.monotonic() - t0:.0f}s {todo[i][1]}", file=sys.stderr
            )


def contrasts(rows: list[dict[str, Any]]) -> dict[tuple, dict[str, Any]]:
    """(candidate, algo, mode) -> per-seed contrasts, their interval and per-arena means."""
    zero = {(r["seed"], r["arena"]): r["score"] for r in rows if r["candidate"] == "zero"}
    groups: dict[tuple, dict[int, list[dict[str, Any]]]] = {}
    for r in rows:
        if r["candidate"] != "zero":
            groups.setdefault((r["candidate"], r["algo"], r["mode"]), {}).setdefault(
                r["seed"], []
            ).append(r)
    out = {}
    for key, by_seed in groups.items():
        per_seed = {
            s: float(np.mean([r["score"] - zero[(s, r["arena"])] for r in rs]))
            for s, rs in sorted(by_seed.items())
        }
        arena: dict[str, list[float]] = {}
        for s, rs in by_seed.items():
            for r in rs:
                if r["role"] == "own":
                    arena.setdefault(r["robot"], []).append(r["score"] - zero[(s, r["arena"])])
        fwd = [r["fwd_share"] for rs in by_seed.values() for r in rs if "fwd_share" in r]
        g0 = [r["greedy0"] for rs in by_seed.values() for r in rs]
        out[key] = {
            "seeds": per_seed,
            "interval": interval(list(per_seed.values())),
            "arena_own": {a: float(np.mean(v)) for a, v in sorted(arena.items())},
            "fwd_share": float(np.mean(fwd)) if fwd else float("nan"),
            "greedy0_forward": float(np.mean([g == 0 for g in g0])),
            "cpu": sum(
                rs[0]["train_cpu"]
                if key[2] == "federated"
                else sum(r["train_cpu"] for r in rs if r["arena"] == r["robot"])
                for rs in by_seed.values()
            ),
        }
    return out


def summary(out: Path) -> str:
    """The measured table as Markdown."""
    lines = [
        "| candidate | algo | mode | contrast (mean ± 95% t, n seeds) | per seed | "
        "own arena r1..r5 | open-floor greedy forward | train CPU s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for (c, algo, mode), v in sorted(contrasts(read_rows(out)).items()):
        iv = v["interval"]
        lines.append(
            f"| {c} | {algo} | {mode} | {iv.mean:+.3f} ± {iv.half:.3f} (n={iv.n}) | "
            + " ".join(f"{x:+.2f}" for x in v["seeds"].values())
            + " | "
            + " ".join(f"{x:+.2f}" for x in v["arena_own"].values())
            + " | "
            + f"{v['greedy0_forward']:.2f} | {v['cpu']:.0f} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="control_study", description=__doc__.split("\n")[0])
    sub = p.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("run")
    r.add_argument("out", type=Path)
    r.add_argument("--candidates", nargs="+", default=["shuffle", "centred"])
    r.add_argument("--algos", nargs="+", default=["qlearning", "sarsa"])
    r.add_argument(
        "--modes", nargs="+", default=["standalone"], choices=["standalone", "federated"]
    )
    r.add_argument("--seeds", nargs="+", type=int, default=[1, 2, 3, 4, 5])
    r.add_argument("--iterations", type=int, default=15_000)
    r.add_argument("--jobs", type=int, default=2, choices=[1, 2])
    s = sub.add_parser("summary")
    s.add_argument("out", type=Path)
    a = p.parse_args(argv)
    if a.cmd == "run":
        run(a.out, a.candidates, a.algos, a.seeds, a.modes, a.iterations, a.jobs)
    print(summary(a.out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
