"""``dfrl sweep``, ``paper``, ``speedup``: studies with several seeds
(:mod:`dfrl.experiments.science.studies`); ``dfrl reference``: an arena's reference table
(:mod:`dfrl.experiments.science.reference`)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from dfrl.experiments.cli.cluster import add_study_cluster_arguments, study_cluster
from dfrl.experiments.cli.figures import add_figure_arguments, redraw_paper
from dfrl.experiments.cli.seeds import add_seed_arguments, chosen_seeds
from dfrl.experiments.cli.sim_option import add_sim_argument, chosen_sim
from dfrl.experiments.provenance import write_provenance

if TYPE_CHECKING:
    from collections.abc import Callable, Sequence

    from dfrl.experiments.science.reference import Reference
    from dfrl.experiments.science.studies.speedup import SpeedupOptions
    from dfrl.experiments.science.studies.speedup_report import SpeedupRow


def parse_factor(text: str) -> tuple[str, list[Any]]:
    """``PATH=V1;V2;...`` with JSON values (a bare word is a string)."""
    path, sep, values = text.partition("=")
    if not sep or not path or not values:
        raise argparse.ArgumentTypeError(f"expected PATH=V1;V2;..., got {text!r}")
    out: list[Any] = []
    for v in values.split(";"):
        try:
            out.append(json.loads(v))
        except json.JSONDecodeError:
            out.append(v)
    return path, out


#: ``dfrl paper --budget long``: iterations per robot (robots/README.md, "Budget").
LONG_BUDGET = 150_000

DEFAULT_FACTORS = [
    "learner.alpha=0.05;0.1;0.4",
    "learner.gamma=0.8;0.9;0.99",
    'learner.epsilon={"kind":"linear","start":1.0,"end":0.05,"decay_steps":10000};'
    '{"kind":"constant","start":0.1,"end":0.1,"decay_steps":1}',
    "reward.alive_bonus=0.0",
    "discretisation.grouping=five;eight",
]


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "sweep",
        help="hyper-parameter sweep: several seeds per setting, scored by greedy "
        "progress and collisions in own and held-out arenas",
        description="Train standalone robots under several settings (one factor at a time "
        "around the defaults, or a grid), several seeds each, and report the "
        "greedy policy's performance with 95% intervals (markdown table).",
    )
    p.add_argument(
        "--set",
        dest="factors",
        action="append",
        type=parse_factor,
        default=None,
        metavar="PATH=V1;V2",
        help="a factor: a dotted path into the training "
        "config and its levels, JSON values separated by ';' (repeatable; default: "
        "learning rate, discount, exploration, reward alive bonus, state grouping)",
    )
    p.add_argument(
        "--mode",
        choices=("ofat", "grid"),
        default="ofat",
        help="one factor at a time around the base, or every combination (default: %(default)s)",
    )
    p.add_argument("--arena", default="r4", help="training arena (default: %(default)s)")
    p.add_argument("--algo", default="qlearning", help="learner (default: %(default)s)")
    p.add_argument(
        "--iterations",
        type=int,
        default=20000,
        help="training iterations per run (default: %(default)s)",
    )
    add_seed_arguments(p, 3)
    p.add_argument(
        "--eval-steps",
        type=int,
        default=2000,
        help="evaluation steps per snapshot and arena (default: %(default)s)",
    )
    p.add_argument(
        "--held-out",
        nargs="*",
        default=["h1", "h2"],
        help="held-out evaluation arenas (default: %(default)s)",
    )
    p.add_argument(
        "--jobs", type=int, default=2, help="processes of --sim pybullet (default: %(default)s)"
    )
    add_sim_argument(p)
    p.add_argument(
        "--out", type=Path, default=None, help="also write sweep.md and sweep.json into this folder"
    )
    p.add_argument("--json", action="store_true", help="print JSON instead of the table")
    p.set_defaults(func=cmd_sweep)
    register_paper(subparsers)
    register_speedup(subparsers)
    register_reference(subparsers)


def cmd_sweep(args: argparse.Namespace) -> int:
    from dfrl.experiments.science.studies.sweep import markdown_table, sweep
    from dfrl.robots.training import TrainerConfig

    factors = dict(args.factors or [parse_factor(f) for f in DEFAULT_FACTORS])
    try:
        seeds = chosen_seeds(args)
        base = TrainerConfig(arena=args.arena, algo=args.algo, iterations=args.iterations).to_dict()
        sim = chosen_sim(args)
        results = sweep(
            base,
            factors,
            list(seeds),
            args.mode,
            tuple(args.held_out),
            args.eval_steps,
            jobs=args.jobs,
            sim=sim,
        )
    except (KeyError, ValueError, TypeError) as exc:
        print(f"dfrl sweep: {exc}", file=sys.stderr)
        return 2
    data = [
        {
            "setting": r.setting.name,
            "changes": [list(c) for c in r.setting.changes],
            "sim": sim,
            "runs": r.runs,
        }
        for r in results
    ]
    table = markdown_table(results) + f"\n\nSimulator: {sim}."
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        write_provenance(args.out)
        (args.out / "sweep.json").write_text(json.dumps(data, indent=1), encoding="utf-8")
        (args.out / "sweep.md").write_text(table + "\n", encoding="utf-8")
    print(json.dumps(data, indent=1) if args.json else table)
    return 0


def register_paper(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "paper",
        help="the paper's experiment with K seeds: questions L, F, T, M answered by "
        "contrasts against controls, with intervals, Holm and power",
        description="Federated (Q-learning/SARSA x average/max, Q-learning/visit_average) and "
        "standalone robots K times, the untrained table and a learning control per "
        "algorithm and setting, through the same pipeline; report.md answers L (do "
        "robots learn), F (does federation help), T (do federated tables transfer "
        "better), M (which method), each row a contrast paired by seed with its "
        "interval, Holm-adjusted p, verdict and the power it had "
        "(experiments/science/README.md, 'Questions'). --from DIR judges a study "
        "again from DIR/evaluations.csv without running anything. Exit 1 if a "
        "federated run failed.",
    )
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="output folder (default: results/paper; with --from: DIR)",
    )
    p.add_argument(
        "--from",
        dest="source",
        type=Path,
        default=None,
        metavar="DIR",
        help="judge the questions again from DIR/evaluations.csv (no run); writes "
        "questions.md, questions.csv and contrasts_by_seed.csv into --out",
    )
    p.add_argument(
        "--delta",
        action="append",
        default=[],
        metavar="Q=EFFECT",
        help="smallest effect of interest of question Q (L, F, T or M), in greedy "
        "score units (default: 0.1 each); repeat for several",
    )
    add_seed_arguments(p, 5)
    p.add_argument(
        "--iterations",
        type=int,
        default=None,
        help="iterations per robot (default: 10000, see --budget)",
    )
    p.add_argument(
        "--budget",
        choices=("paper", "long"),
        default="paper",
        help="paper: 10,000 iterations (five seeds of everything within 15 minutes "
        "on 2 cores); long: 150,000, where the sum of Q-values of "
        "one robot flattens (robots/README.md, 'Budget'); --iterations "
        "overrides both (default: %(default)s)",
    )
    p.add_argument(
        "--respite",
        type=int,
        default=None,
        help="iterations between two shares (default: the configs', 500)",
    )
    p.add_argument(
        "--eval-points",
        type=int,
        default=2,
        help="greedy evaluations per run, evenly spaced; the last one also in the "
        "held-out arenas (default: %(default)s)",
    )
    p.add_argument(
        "--eval-steps",
        type=int,
        default=1000,
        help="evaluation steps per table and arena (default: %(default)s)",
    )
    p.add_argument(
        "--resamples",
        type=int,
        default=2000,
        help="bootstrap resamples of the report's rliable intervals (default: %(default)s)",
    )
    p.add_argument(
        "--jobs",
        type=int,
        default=2,
        help="processes for standalone runs and evaluations (default: %(default)s)",
    )
    p.add_argument(
        "--no-control",
        action="store_true",
        help="skip the untrained table and the learning controls (question L then "
        "cannot be judged)",
    )
    p.add_argument(
        "--driver",
        action="store_true",
        help="run every federated run through `dfrl run` (robot processes and the "
        "dFRL agent) instead of the bit-identical in-process replica",
    )
    p.add_argument(
        "--diagnostics",
        action="store_true",
        help="also run the off-policy reference (Q-learning from random behaviour, "
        "epsilon 1), a diagnostic",
    )
    p.add_argument(
        "--shuffle-buffer",
        type=int,
        default=None,
        metavar="W",
        help="the learning control's buffer of observed rewards (default: 1000)",
    )
    p.add_argument(
        "--skip-existing", action="store_true", help="reuse finished runs found in --out"
    )
    p.add_argument(
        "--sim",
        choices=("pybullet", "batched"),
        default="pybullet",
        help="pybullet: every run's folder, curves and figures; batched: every run "
        "of every seed in one batch on the batched simulator (a minute for 40 "
        "seeds), evaluations.csv and the questions only, no --driver or "
        "--cluster (default: %(default)s)",
    )
    p.add_argument(
        "--confirm-seeds",
        type=int,
        default=0,
        metavar="K",
        help="with --sim batched: run questions F and T again on pybullet with the "
        "first K seeds and say, row by row, whether the two agree (about 3 "
        "minutes of pybullet per seed; 0: off) (default: 0)",
    )
    add_study_cluster_arguments(p)
    add_figure_arguments(p)
    p.set_defaults(func=cmd_paper)


def parse_deltas(items: list[str]) -> dict[str, float]:
    """``["F=0.05", ...]`` -> ``{"F": 0.05}``.

    Raises
    ------
    ValueError
        Not ``Q=EFFECT``, an unknown question, or an effect that is not a number > 0.
    """
    out = {}
    for item in items:
        q, sep, value = item.partition("=")
        q = q.strip().upper()
        if not sep or q not in ("L", "F", "T", "M"):
            raise ValueError(f"--delta {item!r}: expected Q=EFFECT with Q one of L, F, T, M")
        try:
            effect = float(value)
        except ValueError:
            raise ValueError(f"--delta {item!r}: {value!r} is not a number") from None
        if not (effect > 0 and effect < float("inf")):
            raise ValueError(f"--delta {item!r}: the effect must be a number > 0")
        out[q] = effect
    return out


def cmd_paper(args: argparse.Namespace) -> int:
    """``dfrl paper``: exit 0 when every federated run succeeded (``--from``: when the
    evaluations could be read)."""
    from dfrl.experiments.errors import ExperimentError
    from dfrl.experiments.science.reproduce import PAPER_ITERATIONS, PaperOptions, reproduce_paper

    try:
        deltas = parse_deltas(args.delta)
        if args.resamples < 100:
            raise ValueError(
                f"--resamples {args.resamples}: at least 100 (an interval's ends "
                "from fewer resamples move from seed to seed)"
            )
        if args.source is not None:
            return _rejudge(args, deltas)
        seeds = chosen_seeds(args)
        cluster = study_cluster(args)
    except ValueError as exc:
        print(f"dfrl paper: {exc}", file=sys.stderr)
        return 2
    if args.out is None:
        args.out = Path("results/paper")
    opts = PaperOptions(
        seeds=seeds,
        cluster=cluster,
        iterations=args.iterations
        if args.iterations is not None
        else (LONG_BUDGET if args.budget == "long" else PAPER_ITERATIONS),
        respite=args.respite,
        points=args.eval_points,
        eval_steps=args.eval_steps,
        jobs=args.jobs,
        control=not args.no_control,
        diagnostics=args.diagnostics,
        driver=args.driver,
        resamples=args.resamples,
        skip_existing=args.skip_existing,
        deltas=tuple(deltas.items()),
        **({} if args.shuffle_buffer is None else {"shuffle_buffer": args.shuffle_buffer}),
    )
    if args.sim == "batched":
        return _batched_paper(args.out, opts, args.confirm_seeds)
    if args.confirm_seeds:
        print(
            "dfrl paper: --confirm-seeds confirms a --sim batched study on pybullet",
            file=sys.stderr,
        )
        return 2
    try:
        done = reproduce_paper(args.out, opts)
    except (ExperimentError, FileNotFoundError, ValueError) as exc:
        print(f"dfrl paper: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as exc:  # SIGTERM or Ctrl-C: the whole study stopped
        print(
            f"dfrl paper: stopped ({exc or 'interrupted'}); finished runs are in "
            f"{args.out} (--skip-existing reuses them)",
            file=sys.stderr,
        )
        return 130
    redraw_paper(args.out, done, args)
    print(f"dfrl paper done in {done.total_s:.0f} s", file=sys.stderr)
    print(done.report)
    return 0 if done.ok else 1


def _batched_paper(out: Path, opts: Any, confirm_seeds: int) -> int:
    """``dfrl paper --sim batched``: run, print the report's path; 2 for options it cannot
    run."""
    from dfrl.experiments.science.paper_batched import batched_paper
    from dfrl.experiments.science.studies.confirm import disagreeing

    try:
        done = batched_paper(out, opts, sys.stderr, confirm_seeds)
    except ValueError as exc:
        print(f"dfrl paper: {exc}", file=sys.stderr)
        return 2
    print(
        f"dfrl paper (batched) done in {done.total_s:.0f} s, {done.robots} robots", file=sys.stderr
    )
    for c in disagreeing(done.confirmation):
        print(
            f"dfrl paper: {c.contrast}: pybullet disagrees with the batched simulator",
            file=sys.stderr,
        )
    print(done.report)
    return 0


def _rejudge(args: argparse.Namespace, deltas: dict[str, float]) -> int:
    """``dfrl paper --from DIR``: judge again, print the summary and the report's path."""
    from dfrl.experiments.science.questions.evaluations import EvaluationsError
    from dfrl.experiments.science.reproduce import rejudge

    out = args.out if args.out is not None else args.source
    try:
        ans, path = rejudge(args.source, deltas, out, resamples=args.resamples)
    except (EvaluationsError, OSError) as exc:
        print(f"dfrl paper --from: {exc}", file=sys.stderr)
        return 2
    for run, verdict in ans.learns().items():
        print(f"L  {run}: {verdict}")
    for c in ans.checks:
        print(f"check  {c.row.a}: {c.words()}")
    for q in ("F", "T", "M"):
        for a in ans.questions.get(q, []):
            print(f"{q}  {a.row.label}: {a.judged.words()}")
    print(path)
    return 0


def register_speedup(subparsers: argparse._SubParsersAction) -> None:
    from dfrl.experiments.science.studies.speedup import CONDITIONS, SpeedupOptions, parse_budget

    d = SpeedupOptions()
    p = subparsers.add_parser(
        "speedup",
        help="samples to a fixed table error (and a greedy score) against the "
        "number of robots, homogeneous and heterogeneous, against linear "
        "speed-up (Kaplan-Meier times, bootstrap intervals, verdicts)",
        description="N robots learn in one process and share every --share-every "
        "iterations; table error against the R1 reference every --grid, greedy "
        "score in R1 every --score-every; runs that never reach a target are "
        "censored (science/README.md, 'Speed-up').",
    )
    p.add_argument(
        "--robots",
        type=int,
        nargs="+",
        default=list(d.robots),
        help="robot counts, 1 included (default: %(default)s)",
    )
    p.add_argument(
        "--conditions",
        nargs="+",
        choices=CONDITIONS,
        default=list(d.conditions),
        help="homogeneous: all robots in r1; heterogeneous: r1..r5 in turn (default: both)",
    )
    add_seed_arguments(p, len(d.seeds))
    p.add_argument(
        "--iterations",
        type=int,
        default=d.iterations,
        help="budget per robot; a run stops earlier once every target is reached "
        "(default: %(default)s)",
    )
    p.add_argument(
        "--budget",
        type=parse_budget,
        action="append",
        default=None,
        metavar="N=ITER",
        help="another budget at N (repeatable; default: 1=36000)",
    )
    p.add_argument(
        "--targets",
        type=float,
        nargs="+",
        default=list(d.targets),
        help="relative table errors to reach (default: %(default)s)",
    )
    p.add_argument(
        "--alpha",
        type=float,
        default=None,
        help="learning rate of every robot (default: the learner's, 0.2)",
    )
    p.add_argument("--method", default=d.method, help="aggregation (default: %(default)s)")
    for flag, kind, hint in (
        ("--share-every", int, "local steps K between two shares"),
        ("--grid", int, "iterations between two table-error measurements"),
        ("--score-threshold", float, "greedy score in r1 to reach"),
        ("--score-every", int, "iterations between greedy evaluations (a multiple of --grid)"),
        ("--eval-steps", int, "steps per greedy evaluation"),
        ("--linear-fraction", float, "'linear speed-up' means T(1)/T(N) > this x N"),
        ("--resamples", int, "bootstrap resamples"),
        ("--jobs", int, "processes"),
    ):
        p.add_argument(
            flag,
            type=kind,
            default=getattr(d, flag[2:].replace("-", "_")),
            help=f"{hint} (default: %(default)s)",
        )
    add_sim_argument(p, "; --resume and --from-runs refuse federations of the other one")
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="also write speedup.md, "
        "speedup.json, tidy.csv, provenance.json there, and each federation to "
        "speedup_runs.jsonl as it ends",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="reuse the federations of --out's speedup_runs.jsonl run with the same options",
    )
    p.add_argument(
        "--from-runs",
        type=Path,
        default=None,
        metavar="FILE",
        help="only analyse a speedup_runs.jsonl (the options it ran with)",
    )
    p.add_argument(
        "--confirm-seeds",
        type=int,
        default=0,
        metavar="K",
        help="then run the headline, T(1)/T(N) at the largest N, homogeneous, "
        "again on pybullet with the first K seeds (N = 1 and that N only) "
        "and report whether it agrees; with --sim batched only; e.g. 5 "
        "(minutes per seed at the defaults) (default: 0, off)",
    )
    p.set_defaults(func=cmd_speedup)


def cmd_speedup(args: argparse.Namespace) -> int:
    """``dfrl speedup``: 0 done, 2 bad options or reference, 130 stopped by a signal."""
    import signal
    import time

    from dfrl.experiments.science.reference import ReferenceError
    from dfrl.experiments.science.reference_store import reference_table
    from dfrl.experiments.science.studies.confirm import check_confirm
    from dfrl.experiments.science.studies.speedup import REFERENCE, SpeedupOptions, study_runs
    from dfrl.experiments.science.studies.speedup_report import (
        analyse,
        markdown,
        progress_line,
        tidy_rows,
        to_json,
    )
    from dfrl.experiments.science.tidy import TIDY_FILE, write_tidy

    try:
        opts = SpeedupOptions(
            robots=tuple(args.robots),
            seeds=chosen_seeds(args),
            conditions=tuple(dict.fromkeys(args.conditions)),
            iterations=args.iterations,
            budgets=SpeedupOptions.budgets if args.budget is None else tuple(args.budget),
            share_every=args.share_every,
            grid=args.grid,
            targets=tuple(args.targets),
            score_threshold=args.score_threshold,
            score_every=args.score_every,
            eval_steps=args.eval_steps,
            alpha=args.alpha,
            method=args.method,
            linear_fraction=args.linear_fraction,
            resamples=args.resamples,
            jobs=args.jobs,
            sim=chosen_sim(args),
        )
        opts.check()
        check_confirm(opts.sim, args.confirm_seeds, len(opts.seeds))
        ref = reference_table(**REFERENCE)
    except (ValueError, KeyError, ReferenceError) as exc:
        print(f"dfrl speedup: {exc}", file=sys.stderr)
        return 2

    def progress(done: int, total: int, run: dict[str, Any]) -> None:
        print(f"[{done}/{total}] {progress_line(run)}", file=sys.stderr, flush=True)

    def stop(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt(f"signal {signum}")

    old = signal.signal(signal.SIGTERM, stop)
    t0 = time.monotonic()
    try:
        results = study_runs(opts, ref, args.out, args.resume, args.from_runs, progress)
    except (OSError, ValueError) as exc:
        print(f"dfrl speedup: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        print(f"dfrl speedup: stopped ({exc or 'interrupted'})", file=sys.stderr)
        return 130
    finally:
        signal.signal(signal.SIGTERM, old)
    wall = time.monotonic() - t0
    rows = analyse(opts, results)
    text = markdown(rows, opts, wall, ref.name)
    extra: dict[str, Any] = {"reference": ref.name, "wall_s": wall}
    if args.confirm_seeds:
        found = _confirm_speedup(opts, rows, ref, args.confirm_seeds, progress, stop)
        if found is None:
            return 130
        extra["confirmation"], section = found
        text += "\n\n" + section
    if args.out is not None:
        args.out.mkdir(parents=True, exist_ok=True)
        write_provenance(args.out)
        write_tidy(args.out / TIDY_FILE, tidy_rows(opts, results))
        (args.out / "speedup.md").write_text(text + "\n", encoding="utf-8")
        data = to_json(rows, opts, results, extra)
        (args.out / "speedup.json").write_text(json.dumps(data, indent=1), encoding="utf-8")
    print(text)
    return 0


def _confirm_speedup(
    opts: SpeedupOptions,
    rows: Sequence[SpeedupRow],
    ref: Reference,
    seeds: int,
    progress: Callable[[int, int, dict[str, Any]], None],
    stop: Callable[[int, Any], None],
) -> tuple[list[dict[str, Any]], str] | None:
    """``--confirm-seeds``: the confirmation's JSON and report section (None: stopped by a
    signal); a disagreement is said on stderr, the exit status stays 0 (the study has no
    failed checks)."""
    import signal
    import time

    from dfrl.experiments.science.studies import confirm

    print(f"dfrl speedup: confirming on pybullet with {seeds} seeds", file=sys.stderr)
    old = signal.signal(signal.SIGTERM, stop)
    t0 = time.monotonic()
    try:
        found = confirm.confirm_speedup(opts, rows, ref, seeds, progress)
    except KeyboardInterrupt as exc:
        print(f"dfrl speedup: confirmation stopped ({exc or 'interrupted'})", file=sys.stderr)
        return None
    finally:
        signal.signal(signal.SIGTERM, old)
    for c in confirm.disagreeing(found):
        print(
            f"dfrl speedup: confirmation: {c.contrast}: pybullet disagrees with batched",
            file=sys.stderr,
        )
    section = confirm.markdown(
        found, confirm.speedup_design(opts, seeds), time.monotonic() - t0, "###"
    )
    return [c.to_dict() for c in found], section


def register_reference(subparsers: argparse._SubParsersAction) -> None:
    from dfrl.experiments.science.reference import (
        DEFAULT_ITERATIONS,
        DEFAULT_MIN_VISITS,
        DEFAULT_SEEDS,
    )

    p = subparsers.add_parser(
        "reference",
        help="build (or check) the reference Q-table of an arena: the mean of "
        "long standalone runs over several seeds, cached with checksums",
        description="The reference table that table errors are measured against "
        "(experiments/science/reference.py): K standalone runs, averaged per "
        "state-action pair over the runs that updated it, stored in the cache "
        "folder with a JSON sidecar (recipe, sha256 of each array). A cached "
        "reference is loaded and verified instead of rebuilt; a checksum mismatch "
        "is exit 1 naming the file.",
    )
    p.add_argument("--arena", default="r1", help="arena name or file (default: %(default)s)")
    p.add_argument("--algo", default="qlearning", help="tabular learner (default: %(default)s)")
    p.add_argument(
        "--iterations",
        type=int,
        default=DEFAULT_ITERATIONS,
        help="iterations per run (default: %(default)s)",
    )
    add_seed_arguments(p, DEFAULT_SEEDS)
    p.add_argument(
        "--min-visits",
        type=int,
        default=DEFAULT_MIN_VISITS,
        help="pairs updated fewer times (summed over the runs) are left out of "
        "the error (default: %(default)s)",
    )
    p.add_argument(
        "--cache",
        type=Path,
        default=None,
        help="cache folder (default: $DFRL_REFERENCE_CACHE, else ~/.cache/dfrl/references)",
    )
    p.add_argument("--rebuild", action="store_true", help="build even if cached")
    p.add_argument("--jobs", type=int, default=1, help="processes (default: %(default)s)")
    p.add_argument("--json", action="store_true", help="print the sidecar's facts as JSON")
    p.set_defaults(func=cmd_reference)


def cmd_reference(args: argparse.Namespace) -> int:
    """``dfrl reference``: exit 0 with the reference's path, 2 on a bad recipe, 1 when the
    cached copy fails verification."""
    from dfrl.experiments.science.reference import (
        SHIPPED,
        ReferenceError,
        default_cache,
        reference_name,
        reference_recipe,
    )
    from dfrl.experiments.science.reference_store import reference_table

    try:
        seeds = chosen_seeds(args)
        name = reference_name(
            reference_recipe(
                args.arena, args.algo, args.iterations, seeds, min_visits=args.min_visits
            )
        )
        folder = args.cache or default_cache()
        cached = not args.rebuild and any(
            (place / f"{name}.json").is_file() for place in (folder, SHIPPED)
        )
        ref = reference_table(
            args.arena,
            args.algo,
            args.iterations,
            seeds,
            cache=args.cache,
            min_visits=args.min_visits,
            jobs=args.jobs,
            rebuild=args.rebuild,
        )
    except ReferenceError as exc:
        print(f"dfrl reference: {exc}", file=sys.stderr)
        return 1
    except (KeyError, ValueError) as exc:
        print(f"dfrl reference: {exc}", file=sys.stderr)
        return 2
    counted = int((ref.visits >= args.min_visits).sum())
    facts = {
        "path": str(ref.path),
        "cached": cached,
        "arena": ref.recipe["arena"],
        "algo": ref.recipe["algo"],
        "iterations": ref.recipe["iterations"],
        "seeds": ref.recipe["seeds"],
        "pairs_counted": counted,
        "pairs_visited": int((ref.visits > 0).sum()),
        "seed_rms": ref.built.get("seed_rms"),
        "build_seconds": ref.built.get("seconds"),
        "dfrl": ref.built.get("dfrl"),
        "git": ref.built.get("git"),
    }
    if args.json:
        print(json.dumps(facts, indent=1))
    else:
        per_k = 1000 * facts["build_seconds"] / (len(seeds) * args.iterations)
        print(
            f"{facts['path']}\n{facts['arena']} {facts['algo']}: {facts['iterations']} "
            f"iterations x seeds {' '.join(map(str, seeds))}; {counted} pairs updated at "
            f"least {args.min_visits} times ({facts['pairs_visited']} at all); a run's own "
            f"RMS error against it {facts['seed_rms']:.3f}; "
            f"{'loaded and verified; it was ' if cached else ''}built in "
            f"{facts['build_seconds']:.1f} s ({per_k:.2f} s per 1,000 iterations of one run)"
        )
    return 0
