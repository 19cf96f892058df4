"""Standalone robot commands: ``dfrl train``, ``dfrl eval``, ``dfrl baselines``,
``dfrl render-arenas``.

Thin CLI over :mod:`dfrl.robots.training`, :mod:`dfrl.experiments.science.standalone` and
:mod:`dfrl.robots.plots`.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path
from typing import Any

from dfrl.experiments.cli.figures import add_figure_arguments
from dfrl.experiments.cli.tensorboard_option import (
    add_tensorboard_argument,
    write_train_tensorboard,
)
from dfrl.experiments.science.learning_check import DEFAULT_EPISODES, DEFAULT_STEPS
from dfrl.robots.learners import LEARNERS, EpsilonSchedule, LearnerParams, ScheduleKind
from dfrl.robots.training import DEMO_ITERATIONS, TrainerConfig


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``train``, ``eval``, ``baselines`` and ``render-arenas``."""
    p = subparsers.add_parser(
        "train", help="train one robot standalone (Q-learning, SARSA, linear Q or DQN)"
    )
    _add_config_arguments(p)
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="output folder (default results/train/ARENA_ALGO_sSEED)",
    )
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-plot", action="store_true", help="do not draw the learning curves")
    p.add_argument(
        "--gui",
        action="store_true",
        help="watch in a pybullet window (needs a display; not paced to real time)",
    )
    p.add_argument(
        "--eval-episodes",
        type=int,
        default=DEFAULT_EPISODES,
        help="at the end, judge whether the robot learnt: its greedy policy, the "
        "untrained learner's and random actions each drive this many episodes "
        "(default: %(default)s; 0: no verdict)",
    )
    p.add_argument(
        "--eval-steps",
        type=int,
        default=DEFAULT_STEPS,
        help="control steps per evaluation episode (default: %(default)s)",
    )
    add_figure_arguments(p)
    add_tensorboard_argument(p)
    p.set_defaults(func=cmd_train)

    p = subparsers.add_parser(
        "eval", help="greedy learned policy vs random policy: collisions per 1,000 steps"
    )
    _add_config_arguments(p, seed=False)
    p.add_argument(
        "--seeds", type=int, nargs="+", default=[1, 2, 3], help="training seeds (default: 1 2 3)"
    )
    p.add_argument(
        "--steps",
        type=int,
        default=2000,
        help="evaluation steps per policy and seed (default: %(default)s)",
    )
    p.add_argument(
        "--table",
        type=Path,
        default=None,
        help="evaluate this saved table (q_table.npy) or parameter file (params.npy, "
        "linear or dqn) instead of training one per seed",
    )
    p.add_argument("--jobs", type=int, default=2, help="worker processes (default: %(default)s)")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.set_defaults(func=cmd_eval)

    p = subparsers.add_parser(
        "baselines",
        help="standalone Q-learning and SARSA in R1 and R4 (the paper's baseline figures)",
    )
    p.add_argument(
        "--out",
        type=Path,
        default=Path("results/baselines"),
        help="output folder (default: %(default)s)",
    )
    p.add_argument(
        "--iterations",
        type=int,
        default=20_000,
        help="control steps per run (default: %(default)s)",
    )
    p.add_argument(
        "--seeds",
        type=int,
        nargs="+",
        default=[1],
        help="training seeds, one run per curve and seed; several: mean line and "
        "min-max band (default: 1)",
    )
    p.add_argument(
        "--arenas", nargs="+", default=["r1", "r4"], help="arena names or files (default: r1 r4)"
    )
    p.add_argument(
        "--algos",
        nargs="+",
        choices=sorted(LEARNERS),
        default=["qlearning", "sarsa"],
        help="learners, one figure each (default: qlearning sarsa)",
    )
    p.add_argument("--jobs", type=int, default=2, help="worker processes (default: %(default)s)")
    add_figure_arguments(p)
    p.set_defaults(func=cmd_baselines)

    p = subparsers.add_parser(
        "render-arenas", help="draw a top view of each arena (PNG, or PDF/SVG with --figure-format)"
    )
    p.add_argument(
        "--out",
        type=Path,
        default=Path("results/arenas"),
        help="output folder (default: %(default)s)",
    )
    p.add_argument(
        "--arena",
        nargs="+",
        default=None,
        help="arena names or files (default: every built-in arena)",
    )
    p.add_argument(
        "--size", type=int, default=480, help="image size in pixels (default: %(default)s)"
    )
    p.add_argument(
        "--rays",
        action="store_true",
        help="draw the e-puck's sensor rays at the start pose (default: off)",
    )
    add_figure_arguments(p)
    p.set_defaults(func=cmd_render_arenas)


def _add_config_arguments(p: argparse.ArgumentParser, seed: bool = True) -> None:
    from dfrl.robots.env import ActionSet, CollisionResponse
    from dfrl.robots.state import SensorGrouping

    d = TrainerConfig()
    g = p.add_argument_group("run")
    g.add_argument(
        "--config",
        type=Path,
        default=None,
        help="a config.json written by a previous run (flags below override it)",
    )
    g.add_argument(
        "--arena", default=None, help=f"arena name (r1..r5) or JSON file (default {d.arena})"
    )
    g.add_argument(
        "--algo", choices=sorted(LEARNERS), default=None, help=f"learner (default {d.algo})"
    )
    g.add_argument(
        "--iterations",
        type=int,
        default=None,
        help=f"control steps of 64 ms (default {DEMO_ITERATIONS})",
    )
    if seed:
        g.add_argument("--seed", type=int, default=None, help="random seed (default 0)")
    g = p.add_argument_group("learner")
    g.add_argument(
        "--alpha",
        type=float,
        default=None,
        help=f"learning rate of the tabular learners ({d.learner.alpha})",
    )
    g.add_argument("--gamma", type=float, default=None, help=f"discount ({d.learner.gamma})")
    g.add_argument(
        "--epsilon-schedule",
        choices=[k.value for k in ScheduleKind],
        default=None,
        help=f"exploration schedule (default {d.learner.epsilon.kind.value})",
    )
    g.add_argument("--epsilon-start", type=float, default=None, help=f"({d.learner.epsilon.start})")
    g.add_argument("--epsilon-end", type=float, default=None, help=f"({d.learner.epsilon.end})")
    g.add_argument(
        "--epsilon-decay",
        type=int,
        default=None,
        help=f"decay steps ({d.learner.epsilon.decay_steps})",
    )
    g = p.add_argument_group("function-approximation learners (linear, dqn)")
    g.add_argument(
        "--linear-alpha",
        type=float,
        default=None,
        help=f"linear: fraction of the TD error per update ({d.linear.alpha})",
    )
    g.add_argument(
        "--tilings",
        type=int,
        default=None,
        help=f"linear: offset tilings per sensor ({d.linear.tilings})",
    )
    g.add_argument(
        "--tiles", type=int, default=None, help=f"linear: tiles per tiling ({d.linear.tiles})"
    )
    g.add_argument(
        "--hidden",
        type=int,
        nargs="+",
        default=None,
        help=f"dqn: hidden layer widths ({' '.join(map(str, d.dqn.hidden))})",
    )
    for flag, kind, what in (
        ("lr", float, "Adam step size"),
        ("batch_size", int, "transitions per gradient step"),
        ("buffer_size", int, "replay capacity"),
        ("learning_starts", int, "transitions before the first gradient step"),
        ("train_every", int, "environment steps per gradient step"),
        ("target_update", int, "gradient steps between target network copies"),
    ):
        g.add_argument(
            "--" + flag.replace("_", "-"),
            type=kind,
            default=None,
            help=f"dqn: {what} ({getattr(d.dqn, flag)})",
        )
    g = p.add_argument_group("state, actions, simulation")
    g.add_argument(
        "--grouping",
        choices=[s.value for s in SensorGrouping],
        default=None,
        help=f"sensor groups ({d.discretisation.grouping.value})",
    )
    g.add_argument(
        "--levels", type=int, default=None, help=f"levels per group ({d.discretisation.levels})"
    )
    g.add_argument(
        "--actions",
        choices=[a.value for a in ActionSet],
        default=None,
        help=f"action set (default {_value(d.actions)})",
    )
    g.add_argument(
        "--collision-response",
        choices=[c.value for c in CollisionResponse],
        default=None,
        help=f"what a collision does (default {_value(d.collision_response)})",
    )
    g.add_argument("--control-dt", type=float, default=None, help=f"s ({d.sim.control_dt})")
    g.add_argument("--physics-dt", type=float, default=None, help=f"s ({d.sim.physics_dt})")
    g.add_argument(
        "--sensor-noise",
        type=float,
        default=None,
        help=f"IR noise std in m ({d.sim.robot.sensor_noise_std})",
    )


def _value(x: Any) -> str:
    """An enum's value, or the thing itself, for a help text."""
    return str(getattr(x, "value", x))


def config_from_args(args: argparse.Namespace) -> TrainerConfig:
    """Build a :class:`TrainerConfig` from ``--config`` and the flags that override it."""
    from dfrl.robots.epuck import EPuckConfig
    from dfrl.robots.state import DiscretisationConfig
    from dfrl.robots.world import SimConfig

    if getattr(args, "config", None) is not None:
        cfg = TrainerConfig.from_dict(json.loads(args.config.read_text(encoding="utf-8")))
    else:
        cfg = TrainerConfig()
    top: dict[str, Any] = {}
    for name in ("arena", "algo", "iterations", "seed", "actions", "collision_response"):
        value = getattr(args, name, None)
        if value is not None:
            top[name] = value
    eps = cfg.learner.epsilon
    eps_changes = {
        k: v
        for k, v in (
            ("kind", args.epsilon_schedule),
            ("start", args.epsilon_start),
            ("end", args.epsilon_end),
            ("decay_steps", args.epsilon_decay),
        )
        if v is not None
    }
    learner_changes: dict[str, Any] = {
        k: v for k, v in (("alpha", args.alpha), ("gamma", args.gamma)) if v is not None
    }
    if eps_changes:
        learner_changes["epsilon"] = EpsilonSchedule(**{**eps.__dict__, **eps_changes})
    if learner_changes:
        top["learner"] = LearnerParams(**{**cfg.learner.__dict__, **learner_changes})
    lin = {
        k: v
        for k, v in (("alpha", args.linear_alpha), ("tilings", args.tilings), ("tiles", args.tiles))
        if v is not None
    }
    if lin:
        top["linear"] = dataclasses.replace(cfg.linear, **lin)
    net = {
        k: getattr(args, k)
        for k in (
            "lr",
            "batch_size",
            "buffer_size",
            "learning_starts",
            "train_every",
            "target_update",
        )
        if getattr(args, k) is not None
    }
    if args.hidden is not None:
        net["hidden"] = tuple(args.hidden)
    if net:
        top["dqn"] = dataclasses.replace(cfg.dqn, **net)
    disc = {
        k: v for k, v in (("grouping", args.grouping), ("levels", args.levels)) if v is not None
    }
    if disc:
        top["discretisation"] = DiscretisationConfig(**{**cfg.discretisation.__dict__, **disc})
    sim = {
        k: v
        for k, v in (("control_dt", args.control_dt), ("physics_dt", args.physics_dt))
        if v is not None
    }
    if args.sensor_noise is not None:
        sim["robot"] = EPuckConfig(
            **{**cfg.sim.robot.__dict__, "sensor_noise_std": args.sensor_noise}
        )
    if getattr(args, "gui", False):
        sim["connection"] = "gui"
    if sim:
        top["sim"] = SimConfig(**{**cfg.sim.__dict__, **sim})
    return cfg.replace(**top) if top else cfg


def _fail(message: str) -> int:
    print(f"dfrl: error: {message}", file=sys.stderr)
    return 2


# -- train -----------------------------------------------------------------------------------
def cmd_train(args: argparse.Namespace) -> int:
    """``dfrl train``: one run, writing table, config, metrics and the learning curves, then
    the verdict on whether the robot learnt (``learning_check.json``; not with
    ``--eval-episodes 0``)."""
    from tqdm import tqdm

    from dfrl.robots.learners import is_tabular
    from dfrl.robots.training import train

    try:
        cfg = config_from_args(args)
    except (ValueError, KeyError) as exc:
        return _fail(str(exc))
    if args.eval_episodes == 1 or args.eval_episodes < 0:
        return _fail(
            f"--eval-episodes: 0 (no verdict) or at least 2 (an interval needs two), "
            f"got {args.eval_episodes}"
        )
    if args.eval_steps < 1:
        return _fail(f"--eval-steps: at least 1, got {args.eval_steps}")
    from dfrl.arenas.spec import ArenaError, load_arena

    try:  # a bad arena is said before a progress bar is drawn
        load_arena(cfg.arena)
    except (ArenaError, OSError) as exc:
        return _fail(f"--arena: {exc}")
    out = args.out or Path("results/train") / f"{Path(cfg.arena).stem}_{cfg.algo}_s{cfg.seed}"
    with tqdm(
        total=cfg.iterations,
        desc=f"{cfg.algo} {cfg.arena} seed {cfg.seed}",
        unit="it",
        disable=args.no_progress,
        file=sys.stderr,
    ) as bar:
        try:
            result = train(cfg, out, progress=bar.update)
        except ValueError as exc:
            return _fail(str(exc))
    m = result.metrics
    summed = "Q-values" if is_tabular(cfg.algo) else "parameters"
    if not args.no_plot and len(m):
        from dfrl.robots.plots import plot_learning_curves

        plot_learning_curves(
            {f"{cfg.arena} {cfg.algo}": m},
            out / "learning_curves.png",
            f"{cfg.algo} in {cfg.arena}, seed {cfg.seed}",
            args.figure_format,
            args.dpi,
            summed=summed,
        )
    if args.tensorboard:
        write_train_tensorboard(out, m, "dfrl train")
    rate = cfg.iterations / result.wall_time if result.wall_time > 0 else float("nan")
    last = m[-1] if len(m) else None
    print(
        f"trained {cfg.algo} in {cfg.arena} for {cfg.iterations} iterations in "
        f"{result.wall_time:.1f} s ({rate:.0f} it/s, "
        f"{rate * cfg.sim.control_dt:.0f}x real time)"
    )
    if last is not None:
        print(
            f"collisions {int(last['collisions'])}, cumulative reward "
            f"{float(last['cumulative_reward']):.1f}, sum of {summed} "
            f"{float(last['q_sum']):.2f}"
        )
    if args.eval_episodes:
        from dfrl.experiments.science.learning_check import check_learning

        check = check_learning(
            cfg, result.q_table, result.params, args.eval_episodes, args.eval_steps
        )
        (out / "learning_check.json").write_text(
            json.dumps(check.to_dict(), indent=2) + "\n", encoding="utf-8"
        )
        for line in check.lines():
            print(line)
    print(f"results in {out}")
    return 0


# -- eval ------------------------------------------------------------------------------------
def cmd_eval(args: argparse.Namespace) -> int:
    """``dfrl eval``: greedy vs random collisions per 1,000 steps, per seed and over all."""
    from dfrl.experiments.science.standalone import evaluate, with_table_discretisation

    try:
        cfg = config_from_args(args)
    except (ValueError, KeyError) as exc:
        return _fail(str(exc))
    table = str(args.table) if args.table is not None else None
    from dfrl.robots.learners import is_tabular
    from dfrl.robots.tables import PARAMS_FORMATS, sidecar_format

    if table is not None and sidecar_format(args.table) in PARAMS_FORMATS:
        return _eval_function_learner(args, cfg, args.table)
    if table is None and not is_tabular(cfg.algo):
        return _eval_function_learner(args, cfg, None)
    if table is not None and args.grouping is None and args.levels is None:
        try:  # evaluate with the table's own discretisation, as recorded in its sidecar
            cfg = with_table_discretisation(cfg, table)
        except (ValueError, OSError, KeyError) as exc:
            return _fail(str(exc))
    try:
        summary = evaluate(cfg, list(args.seeds), args.steps, table, args.jobs)
    except (ValueError, OSError) as exc:  # bad table, arena or configuration
        return _fail(str(exc))
    return _print_eval(args, cfg, summary, table)


def _print_eval(
    args: argparse.Namespace, cfg: TrainerConfig, summary: Any, table: str | None
) -> int:
    """Print a ``dfrl eval`` summary (JSON with ``--json``); 0."""
    if args.json:
        print(json.dumps(summary.to_dict(), indent=2))
        return 0
    src = table or f"{cfg.iterations} training iterations"
    print(f"{cfg.algo} in {cfg.arena}, {src}; {args.steps} evaluation steps per policy")
    print(
        f"{'seed':>4} {'train s':>8} {'greedy coll/1000':>17} {'random coll/1000':>17} "
        f"{'greedy m':>9} {'random m':>9} {'greedy progress':>16} {'greedy coverage':>16}"
    )
    for r in summary.runs:
        g = r["greedy"]
        print(
            f"{r['seed']:>4} {r['train_s']:>8.1f} {g['collisions_per_1000']:>17.2f} "
            f"{r['random']['collisions_per_1000']:>17.2f} {g['distance']:>9.2f} "
            f"{r['random']['distance']:>9.2f} {g['progress']:>16.2f} {g['coverage']:>16.2f}"
        )
    print(
        f"all  {'':>8} {summary.greedy_collisions_per_1000:>17.2f} "
        f"{summary.random_collisions_per_1000:>17.2f}"
    )
    print(f"reduction {100 * summary.reduction:.0f}%")
    return 0


def _eval_function_learner(
    args: argparse.Namespace, cfg: TrainerConfig, params_file: Path | None
) -> int:
    """``dfrl eval`` for ``linear`` and ``dqn``: train per seed (or load ``params_file``), then
    greedy vs random, reported as for the tables (one process: ``--jobs`` is not used)."""
    from dfrl.experiments.science.standalone import EVAL_SEED_OFFSET, EvalSummary
    from dfrl.robots.evaluation import learnt_vs_random
    from dfrl.robots.tables import load_params
    from dfrl.robots.trainer_config import with_params_meta

    params = None
    try:
        if params_file is not None:
            loaded = load_params(params_file)
            cfg, params = with_params_meta(cfg, loaded.meta), loaded.params
        rows = [
            learnt_vs_random(cfg, s, args.steps, EVAL_SEED_OFFSET + s, params) for s in args.seeds
        ]
    except (ValueError, OSError, KeyError, TypeError) as exc:
        return _fail(str(exc))
    total = args.steps * len(rows)
    g_rate = 1000.0 * sum(r["greedy"]["collisions"] for r in rows) / total
    r_rate = 1000.0 * sum(r["random"]["collisions"] for r in rows) / total
    summary = EvalSummary(
        cfg.arena,
        cfg.algo,
        cfg.iterations,
        list(args.seeds),
        args.steps,
        str(params_file) if params_file else None,
        rows,
        g_rate,
        r_rate,
        1.0 - g_rate / r_rate if r_rate > 0 else float("nan"),
    )
    return _print_eval(args, cfg, summary, str(params_file) if params_file else None)


# -- baselines -------------------------------------------------------------------------------
def cmd_baselines(args: argparse.Namespace) -> int:
    """``dfrl baselines``: train every (algo, arena) pair and draw one figure per algorithm."""
    from tqdm import tqdm

    from dfrl.experiments.science.report.stats import ALGO_NAMES
    from dfrl.experiments.science.standalone import run_jobs
    from dfrl.robots.plots import plot_learning_curves
    from dfrl.robots.training import read_metrics_csv

    args.out.mkdir(parents=True, exist_ok=True)
    seeds = list(dict.fromkeys(args.seeds))

    def run_dir(algo: str, arena: str, seed: int) -> Path:
        return args.out / (f"{algo}_{arena}" if len(seeds) == 1 else f"{algo}_{arena}_s{seed}")

    jobs = [
        (TrainerConfig(arena=a, algo=al, seed=s, iterations=args.iterations), run_dir(al, a, s))
        for al in args.algos
        for a in args.arenas
        for s in seeds
    ]
    with tqdm(total=len(jobs), desc="baseline runs", unit="run", file=sys.stderr) as bar:

        def done(algo: str, arena: str, wall: float) -> None:
            bar.update()
            print(f"{algo} {arena}: {args.iterations} iterations in {wall:.1f} s", file=sys.stderr)

        run_jobs(jobs, args.jobs, done)
    for algo in args.algos:
        curves = {
            a.upper(): [read_metrics_csv(run_dir(algo, a, s) / "metrics.csv") for s in seeds]
            for a in args.arenas
        }
        name = ALGO_NAMES.get(algo, algo)
        which = (
            f"seed {seeds[0]}"
            if len(seeds) == 1
            else f"seeds {seeds[0]}-{seeds[-1]}"
            if seeds == list(range(seeds[0], seeds[-1] + 1))
            else "seeds " + ", ".join(map(str, seeds))
        )
        path = plot_learning_curves(
            curves,
            args.out / f"baseline_{algo}.png",
            f"Standalone {name}, {args.iterations} iterations ({which})",
            args.figure_format,
            args.dpi,
        )
        _print_files(path, args.figure_format)
    return 0


# -- render-arenas ---------------------------------------------------------------------------
def cmd_render_arenas(args: argparse.Namespace) -> int:
    """``dfrl render-arenas``: one PNG per arena plus ``arenas.png`` with all of them."""
    from dfrl.arenas.spec import ArenaError, builtin_arena_names, load_arena
    from dfrl.robots.plots import plot_arena, plot_arena_overview
    from dfrl.robots.world import World

    names = args.arena or builtin_arena_names()
    images = {}
    for name in names:
        try:
            spec = load_arena(name)
        except ArenaError as exc:
            return _fail(str(exc))
        world = World(spec)
        rays = None
        try:
            if spec.start.pose is not None:
                world.place_robot(*spec.start.pose)
                if args.rays:  # what the sensors see at the start pose (seeded noise)
                    import numpy as np

                    rays = world.robot.sensor_rays(world.robot.sense(np.random.default_rng(0)))
            else:  # a random start: keep the robot out of the picture
                world.place_robot(10.0 * max(spec.size), 0.0, 0.0)
            img = world.render_top(args.size, args.size)
        finally:
            world.close()
        images[spec.name] = img
        _print_files(
            plot_arena(
                img, spec, args.out / f"arena_{spec.name}.png", rays, args.figure_format, args.dpi
            ),
            args.figure_format,
        )
    _print_files(
        plot_arena_overview(images, args.out / "arenas.png", args.figure_format, args.dpi),
        args.figure_format,
    )
    return 0


def _print_files(first: Path, formats: tuple[str, ...]) -> None:
    """Print every file of a figure written in ``formats`` (``first`` is one of them)."""
    for fmt in formats:
        print(first.with_suffix(f".{fmt}"))
