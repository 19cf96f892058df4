"""``dfrl transfer``: train in a new arena from a saved table and from zeros, compare.

Thin CLI over :func:`dfrl.experiments.science.transfer.run`.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from dfrl.experiments.cli.figures import add_figure_arguments, wants_redraw
from dfrl.experiments.cli.seeds import add_seed_arguments, chosen_seeds
from dfrl.experiments.cli.sim_option import add_sim_argument, chosen_sim
from dfrl.experiments.provenance import write_provenance
from dfrl.robots.learners import LEARNERS
from dfrl.robots.state import SensorGrouping

if TYPE_CHECKING:
    from dfrl.experiments.science.transfer.claims import Claim
    from dfrl.experiments.science.transfer.study import StudyOptions


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``transfer`` and ``transfer-study``."""
    p = subparsers.add_parser(
        "transfer",
        help="learn in a new arena from a saved table vs from zeros (collisions, reward)",
        description="For each seed, train one robot whose Q-table starts as a copy of --init "
        "and one that starts from zeros, in the same arena, with the same seed and "
        "budget; report collisions per 1,000 steps (whole run, first 1,000 steps, "
        "first 10%), cumulative reward and a greedy evaluation after training.",
    )
    p.add_argument(
        "--init", type=Path, required=True, help="saved table (NAME.npy with its NAME.json sidecar)"
    )
    p.add_argument(
        "--arena",
        required=True,
        help="arena name or JSON file, preferably one the table was not trained in",
    )
    p.add_argument(
        "--iterations", type=int, default=3000, help="training steps per run (default: %(default)s)"
    )
    add_seed_arguments(p, 5)  # one run per condition and seed
    p.add_argument(
        "--algo",
        choices=sorted(LEARNERS),
        default=None,
        help="learner (default: the table's algorithm)",
    )
    p.add_argument(
        "--grouping",
        choices=[s.value for s in SensorGrouping],
        default=None,
        help="sensor groups (default: the table's)",
    )
    p.add_argument(
        "--levels", type=int, default=None, help="levels per group (default: the table's)"
    )
    p.add_argument(
        "--eval-steps",
        type=int,
        default=2000,
        help="greedy evaluation steps per table, 0 to skip (default: %(default)s)",
    )
    p.add_argument("--jobs", type=int, default=2, help="worker processes (default: %(default)s)")
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="write config.json, runs.csv, curves.csv, summary.json, transfer.png here",
    )
    p.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    add_figure_arguments(p)
    p.set_defaults(func=cmd_transfer)
    register_study(subparsers)


#: Rows of the readable report: metric name, label.
_ROWS = (
    ("collisions_per_1000", "collisions/1000, training"),
    ("head_collisions_per_1000", "collisions/1000, first {head} steps"),
    ("head10_collisions_per_1000", "collisions/1000, first 10% ({head10})"),
    ("cumulative_reward", "cumulative reward"),
    ("mean_reward", "mean reward per step"),
    ("eval_collisions_per_1000", "greedy eval collisions/1000, after"),
    ("eval_mean_reward", "greedy eval reward per step, after"),
    ("initial_eval_collisions_per_1000", "greedy eval collisions/1000, before"),
    ("initial_eval_mean_reward", "greedy eval reward per step, before"),
)


def _fmt(x: float, width: int = 8) -> str:
    return f"{x:>{width}.2f}" if math.isfinite(x) else f"{'-':>{width}}"


def cmd_transfer(args: argparse.Namespace) -> int:
    """``dfrl transfer``: exit 0 on success, 2 on a bad table, arena or argument."""
    from dfrl.experiments.science.transfer import TransferConfig, run

    try:
        cfg = TransferConfig(
            init=str(args.init),
            arena=args.arena,
            iterations=args.iterations,
            seeds=chosen_seeds(args),
            algo=args.algo,
            grouping=args.grouping,
            levels=args.levels,
            eval_steps=args.eval_steps,
            jobs=args.jobs,
        )
        result = run(cfg, args.out)
    except (ValueError, OSError) as exc:
        print(f"dfrl: error: {exc}", file=sys.stderr)
        return 2
    if result.output_dir is not None and wants_redraw(args):
        from dfrl.experiments.science.transfer import plot_transfer

        try:
            plot_transfer(result, result.output_dir / "transfer.png", args.figure_format, args.dpi)
        except ImportError:
            print("dfrl transfer: figure not drawn: matplotlib is not installed", file=sys.stderr)
    if result.same_arena:
        print(
            f"dfrl: warning: the table was trained in '{result.table.arena}', the arena of "
            f"this transfer",
            file=sys.stderr,
        )
    if args.json:
        print(json.dumps(result.to_dict(), indent=2))
        return 0
    t, tc = result.table, result.trainer_config
    origin = (
        f"{t.algo}, trained in {t.arena} for {t.iterations} iterations"
        if t.sidecar
        else "no sidecar"
    )
    print(
        f"transfer of {t.path} ({origin}) into {result.arena_name}: {tc.algo}, "
        f"{cfg.iterations} iterations x {len(cfg.seeds)} seeds "
        f"({result.wall_time:.0f} s)"
    )
    r0 = result.runs[0]
    print(f"{'':38} {'init mean':>9} {'± std':>7} {'zero mean':>9} {'± std':>7} {'init/zero':>9}")
    for metric, label in _ROWS:
        a, b = result.summary["init"][metric], result.summary["zero"][metric]
        name = label.format(head=r0.head_steps, head10=r0.head10_steps)
        print(
            f"{name:<38} {_fmt(a.mean, 9)} {_fmt(a.std, 7)} {_fmt(b.mean, 9)} {_fmt(b.std, 7)} "
            f"{_fmt(result.ratio[metric], 9)}"
        )
    print(
        f"\n{'seed':>4} {'cond':>5} {'coll/1000':>9} {'head':>8} {'head10%':>8} "
        f"{'cum reward':>10} {'eval after':>10} {'eval before':>11}"
    )
    for r in result.runs:
        print(
            f"{r.seed:>4} {r.condition:>5} {_fmt(r.collisions_per_1000, 9)} "
            f"{_fmt(r.head_collisions_per_1000)} {_fmt(r.head10_collisions_per_1000)} "
            f"{_fmt(r.cumulative_reward, 10)} {_fmt(r.eval_collisions_per_1000, 10)} "
            f"{_fmt(r.initial_eval_collisions_per_1000, 11)}"
        )
    print("(before = the initial table, no training; for zero that is a uniformly random policy)")
    if result.output_dir is not None:
        print(f"results in {result.output_dir}")
    return 0


def register_study(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "transfer-study",
        help="the paper's transfer claim: does a federated table learn unseen arenas (h1, h2) "
        "with fewer collisions and a higher score than standalone tables of every source "
        "arena?",
        description="Source tables per source seed: federated (R1..R5), a matched standalone "
        "table of each source arena (same training seeds) and zeros. From each, a "
        "robot learns in the unseen arenas, with seeds of its source seed's own "
        "(shared by that seed's sources, by no other seed). Primary measures: "
        "collisions while learning and the greedy score while learning (its mean "
        "over the phase). Secondary: the time until the score reaches the arena's "
        "threshold (derived per arena from reference runs unless --threshold, "
        "lifted above every phase's iteration-0 score; censored when never "
        "reached). Paired intervals over source seeds (Welch when unpaired), Holm "
        "within each family, verdicts: holds / refuted (effect excluded at 95%) / "
        "not significant at n = K (smallest detectable effect D) / cannot judge "
        "(the reason: too few seeds, or an interval of zero width).",
    )
    add_seed_arguments(p, 5)  # the source seeds
    p.add_argument(
        "--target-seeds",
        type=int,
        nargs="+",
        default=[1],
        help="learning phases per source seed and unseen arena, 0..499: phase t of "
        "source seed s trains with the seed 1,000,000 + 1,000 s + t "
        "(default: 1)",
    )
    p.add_argument(
        "--targets", nargs="+", default=["h1", "h2"], help="unseen arenas (default: h1 h2)"
    )
    p.add_argument(
        "--iterations",
        type=int,
        default=4000,
        help="source training iterations per robot (default: %(default)s)",
    )
    p.add_argument(
        "--respite",
        type=int,
        default=500,
        help="iterations between two shares of the federation (default: %(default)s)",
    )
    p.add_argument(
        "--method",
        default="average",
        help="aggregation of the federated source (default: %(default)s)",
    )
    p.add_argument(
        "--learn",
        type=int,
        default=2000,
        help="learning steps in each unseen arena (default: %(default)s)",
    )
    p.add_argument(
        "--eval-every",
        type=int,
        default=100,
        help="grid of the greedy score while learning (default: %(default)s)",
    )
    p.add_argument(
        "--eval-steps",
        type=int,
        default=300,
        help="steps of each greedy evaluation (default: %(default)s)",
    )
    p.add_argument(
        "--threshold",
        nargs="+",
        default=[],
        metavar="[ARENA=]SCORE",
        help="greedy score the time is measured to: SCORE for every unseen arena, "
        "ARENA=SCORE for one (default: derived per arena, --threshold-fraction "
        "x the level reference runs from zeros reach in that arena); lifted "
        "above every learning phase's iteration-0 score in the arena",
    )
    p.add_argument(
        "--threshold-fraction",
        type=float,
        default=0.75,
        help="a derived threshold's share of its arena's reference level (default: %(default)s)",
    )
    p.add_argument(
        "--threshold-iterations",
        type=int,
        default=8000,
        help="steps of each reference run (default: %(default)s)",
    )
    p.add_argument(
        "--threshold-runs",
        type=int,
        default=5,
        help="reference runs per unseen arena (default: %(default)s)",
    )
    p.add_argument(
        "--confirm",
        type=int,
        default=2,
        help="evaluations in a row at or above the threshold that count as reaching "
        "it; the time is the first of them (default: %(default)s)",
    )
    p.add_argument(
        "--extra",
        nargs="+",
        default=[],
        choices=["standalone_same_experience", "in_turn", "one_shot_average"],
        help="further controls: one robot in R1 for 5 x --iterations, one robot in "
        "R1..R5 in turn, the mean of five standalone tables",
    )
    p.add_argument(
        "--unpaired",
        action="store_true",
        help="train the controls with other seeds (Welch intervals, not paired)",
    )
    p.add_argument(
        "--resamples",
        type=int,
        default=4000,
        help="bootstrap resamples of a censored difference of times (default: %(default)s)",
    )
    p.add_argument(
        "--jobs", type=int, default=2, help="processes of --sim pybullet (default: %(default)s)"
    )
    add_sim_argument(p, "; --from-json takes the file's and refuses another")
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="write transfer_study.md, transfer_study.json, tidy.csv and provenance.json there",
    )
    p.add_argument(
        "--from-json",
        type=Path,
        default=None,
        metavar="FILE",
        help="judge the learning phases of a transfer_study.json again (its "
        "options; nothing is trained)",
    )
    p.add_argument(
        "--confirm-seeds",
        type=int,
        default=0,
        metavar="K",
        help="then run the headline (the primary claims against the standalone "
        "and zeros controls) again on pybullet with the first K source seeds "
        "and report whether it agrees; a study of the batched simulator "
        "only; e.g. 10 (several minutes) (default: 0, off)",
    )
    p.set_defaults(func=cmd_study)


def thresholds_arg(words: list[str]) -> dict[str, Any]:
    """``--threshold`` words -> ``threshold`` (a bare SCORE) and ``arena_thresholds``
    (ARENA=SCORE).

    Raises
    ------
    ValueError
        A word that is neither, or two bare scores.
    """
    bare, per = [], []
    for w in words:
        arena, eq, value = w.rpartition("=")
        try:
            score = float(value)
        except ValueError:
            raise ValueError(f"--threshold: {w!r} is neither SCORE nor ARENA=SCORE") from None
        if eq:
            per.append((arena, score))
        else:
            bare.append(score)
    if len(bare) > 1:
        raise ValueError(f"--threshold: one SCORE for every arena, got {bare}")
    return {"threshold": bare[0] if bare else None, "arena_thresholds": tuple(per)}


def cmd_study(args: argparse.Namespace) -> int:
    """``dfrl transfer-study``: exit 0 with a report, 2 on a bad option."""
    import time

    from dfrl.experiments.science.studies.confirm import check_confirm
    from dfrl.experiments.science.studies.simulators import LEGACY_SIM, check_same
    from dfrl.experiments.science.transfer.claims import claims, markdown, write_study
    from dfrl.experiments.science.transfer.study import StudyOptions, transfer_study

    t0 = time.perf_counter()
    if args.from_json is not None:
        try:
            doc = json.loads(args.from_json.read_text(encoding="utf-8"))
            # a study written before --sim ran on pybullet
            options = {"sim": LEGACY_SIM, **doc["options"]}
            if args.sim is not None:
                check_same(options["sim"], args.sim, str(args.from_json))
            fields: dict[str, Any] = {
                k: tuple(v) if isinstance(v, list) else v for k, v in options.items()
            }
            opts = StudyOptions(**fields)
            rows, wall = doc["rows"], float(doc["wall_time"])
            found = claims(rows, opts, args.resamples)
            check_confirm(opts.sim, args.confirm_seeds, len(opts.source_seeds))
        except (OSError, ValueError, KeyError, TypeError) as exc:
            said = str(exc) if type(exc) is ValueError else repr(exc)
            print(f"dfrl transfer-study: error: {args.from_json}: {said}", file=sys.stderr)
            return 2
        text = markdown(rows, opts, found, wall)
        confirmation = _confirm(args, opts, rows, found)
        if confirmation is not None:
            text += "\n\n" + confirmation[1]
        if args.out is not None:
            write_provenance(args.out)
            write_study(
                args.out,
                rows,
                opts,
                found,
                text,
                wall,
                None if confirmation is None else confirmation[0],
            )
        print(text)
        return 0
    try:
        opts = StudyOptions(
            source_seeds=chosen_seeds(args),
            target_seeds=tuple(dict.fromkeys(args.target_seeds)),
            targets=tuple(args.targets),
            iterations=args.iterations,
            respite=args.respite,
            method=args.method,
            learn=args.learn,
            eval_every=args.eval_every,
            eval_steps=args.eval_steps,
            **thresholds_arg(args.threshold),
            threshold_fraction=args.threshold_fraction,
            threshold_iterations=args.threshold_iterations,
            threshold_runs=args.threshold_runs,
            confirm=args.confirm,
            unpaired=args.unpaired,
            extra=tuple(args.extra),
            jobs=args.jobs,
            sim=chosen_sim(args),
        )
        check_confirm(opts.sim, args.confirm_seeds, len(opts.source_seeds))
        if args.out is not None:
            args.out.mkdir(parents=True, exist_ok=True)
            write_provenance(args.out)
        rows = transfer_study(opts, lambda msg: print(msg, file=sys.stderr, flush=True))
    except (KeyError, ValueError, OSError) as exc:
        print(f"dfrl transfer-study: error: {exc}", file=sys.stderr)
        return 2
    found = claims(rows, opts, args.resamples)
    wall = time.perf_counter() - t0
    text = markdown(rows, opts, found, wall)
    confirmation = _confirm(args, opts, rows, found)
    if confirmation is not None:
        text += "\n\n" + confirmation[1]
    if args.out is not None:
        write_study(
            args.out,
            rows,
            opts,
            found,
            text,
            wall,
            None if confirmation is None else confirmation[0],
        )
    print(text)
    return 0


def _confirm(
    args: argparse.Namespace, opts: StudyOptions, rows: list[dict[str, Any]], found: list[Claim]
) -> tuple[list[dict[str, Any]], str] | None:
    """``--confirm-seeds``: the confirmation's JSON and report section (None: off). A
    disagreement is said on stderr; the exit status stays 0 (the study has no failed
    checks)."""
    import time

    from dfrl.experiments.science.studies import confirm

    if not args.confirm_seeds:
        return None
    print(
        f"dfrl transfer-study: confirming on pybullet with {args.confirm_seeds} source seeds",
        file=sys.stderr,
    )
    t0 = time.perf_counter()
    confirmed = confirm.confirm_transfer(
        opts,
        rows,
        found,
        args.confirm_seeds,
        args.resamples,
        lambda msg: print(msg, file=sys.stderr, flush=True),
    )
    for c in confirm.disagreeing(confirmed):
        print(
            f"dfrl transfer-study: confirmation: {c.contrast}: pybullet disagrees with batched",
            file=sys.stderr,
        )
    section = confirm.markdown(
        confirmed, confirm.transfer_design(opts, args.confirm_seeds), time.perf_counter() - t0
    )
    return [c.to_dict() for c in confirmed], section
