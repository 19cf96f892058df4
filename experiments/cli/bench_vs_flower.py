"""``dfrl bench vs-flower``: its options and its output (registered in :mod:`.bench`).

The command layer of :mod:`dfrl.experiments.tools.bench.vs_flower`: it alone prints and chooses
the exit status: 0 every pair ran and every dFRL round left the robots identical; 1 a run
failed or a round did not; 2 bad options, or Flower is not installed (the extra ``flower``).
"""

from __future__ import annotations

import argparse
import json
import sys

from dfrl.experiments.tools.bench import vs_flower

NAME = "dfrl bench vs-flower"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``dfrl bench vs-flower``, each help stating its default."""
    parser.add_argument(
        "--sizes",
        type=int,
        nargs="+",
        default=list(vs_flower.SIZES),
        help="floats each client and robot holds, one comparison per size",
    )
    parser.add_argument(
        "--robots",
        type=int,
        nargs="+",
        default=[5],
        help="Flower clients = dFRL robots, one comparison per count (default 5)",
    )
    parser.add_argument(
        "--pairs", type=int, default=3, help="alternating Flower and dFRL runs per size"
    )
    parser.add_argument("--rounds", type=int, default=20, help="timed rounds per run")
    parser.add_argument("--warmup", type=int, default=3, help="untimed rounds first, per run")
    parser.add_argument(
        "--itinerary",
        choices=["chain", "tree"],
        default="chain",
        help="the dFRL agent's itinerary",
    )
    parser.add_argument(
        "--fanout", type=int, default=2, help="children per stop of a tree itinerary"
    )
    parser.add_argument(
        "--json", action="store_true", help="print one JSON object per robot count, one a line"
    )


def _interval(e: dict) -> str:
    if e["ratio_low"] is None:
        return "(one pair: no interval)"
    return f"(95% interval {e['ratio_low']:.2f} to {e['ratio_high']:.2f})"


def _show(r: dict, as_json: bool) -> None:
    """One robot count's comparison: a JSON line, or a table."""
    if as_json:
        print(json.dumps(r), flush=True)
        return
    print(
        f"{r['robots']} clients/robots, Flower {r['flower_version']} FedAvg (gRPC) against "
        f"dFRL {r['itinerary']}; median of {r['rounds']} rounds per run, "
        f"geometric means over the pairs"
    )
    print(f"{'floats':>7}  {'held':<18} {'Flower ms':>9} {'dFRL ms':>9} {'dFRL/Flower':>11}")
    for e in r["sizes"]:
        print(
            f"{e['floats']:>7}  {e['payload']:<18} {e['flower_ms']:>9.2f} "
            f"{e['dfrl_ms']:>9.2f} {e['ratio']:>11.2f} {_interval(e)}"
        )


def cmd(args: argparse.Namespace) -> int:
    missing = vs_flower.flower_missing()
    if missing is not None:
        print(f"{NAME}: {missing}", file=sys.stderr)
        return 2

    def progress(floats: int, k: int, flower_ms: float, dfrl_ms: float) -> None:
        if not args.json:
            print(
                f"  {floats:>7} floats, pair {k}: Flower {flower_ms:8.2f} ms  dFRL "
                f"{dfrl_ms:8.2f} ms  dFRL/Flower {dfrl_ms / flower_ms:6.2f}",
                flush=True,
            )

    problems: list[str] = []
    for robots in args.robots:
        try:
            r = vs_flower.bench(
                tuple(args.sizes),
                robots,
                args.pairs,
                args.rounds,
                args.warmup,
                args.itinerary,
                args.fanout,
                progress=progress,
            )
        except ValueError as exc:
            print(f"{NAME}: {exc}", file=sys.stderr)
            return 2
        except RuntimeError as exc:  # ExperimentError is a RuntimeError
            print(f"{NAME}: {exc}", file=sys.stderr)
            return 1
        _show(r, args.json)
        problems += [
            f"{robots} robots, {e['floats']} floats: {x}" for e in r["sizes"] for x in e["problems"]
        ]
    for problem in problems:
        print(f"{NAME}: {problem}", file=sys.stderr)
    return 1 if problems else 0
