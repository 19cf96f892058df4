"""``dfrl bench faults``: its options and its output (registered in :mod:`.bench`).

The command layer of :mod:`dfrl.experiments.tools.bench.faults`: it alone prints and chooses
the exit status (0 every run of every fault met its expectation, 1 one did not, 2 a bad
option or no network namespaces here).
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
from pathlib import Path
from typing import Any

from dfrl.experiments.tools.bench.faults_cases import CASES


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``dfrl bench faults``, each help stating its default."""
    parser.add_argument(
        "--faults",
        nargs="+",
        choices=list(CASES),
        default=list(CASES),
        help=f"faults to run, in order (default: all, cheapest first: {' '.join(CASES)})",
    )
    parser.add_argument("--runs", type=int, default=3, help="runs of each fault (default 3)")
    parser.add_argument(
        "--rounds",
        type=int,
        default=None,
        help="sync rounds of every run, 5 to 200 (default: each fault's own "
        "plan; 30 for issue 33's cut_holder_*, cut_agent_host_*, "
        "cut_driver_* and kill_driver_collect)",
    )
    parser.add_argument(
        "--itinerary",
        nargs="+",
        choices=["chain", "tree"],
        default=["chain"],
        help="the agent's itineraries, each fault run over each (tree: fan-out 2) (default: chain)",
    )
    parser.add_argument(
        "--hosts", type=int, default=4, help="robot hosts of the federation, 2 to 5 (default 4)"
    )
    parser.add_argument(
        "--delay-ms",
        type=float,
        default=0.0,
        help="hold every chunk into a robot host this many ms each way (a "
        "proxy in the host, in front of its dfrl robot); the time bounds "
        "grow by the run's normal gap between rounds (default 0: none)",
    )
    parser.add_argument(
        "--keep",
        type=Path,
        default=None,
        help="keep every run's files (hosts' folders, results) here "
        "(default: a temporary folder, removed)",
    )
    parser.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object per fault, one a line (default: text)",
    )


def _text(f: dict[str, Any]) -> str:
    med = f["median"]
    delay = f["per_run"][0].get("delay_ms") if f["per_run"] else None
    lines = [
        f"{f['fault']} ({f.get('itinerary', 'chain')}): "
        f"{'PASS' if f['passed'] else 'FAIL'} {f['passed_runs']}/{f['runs']} "
        f"-- {f['what']}" + (f" (links {delay:g} ms slow each way)" if delay else ""),
        f"  median recovery {med['recovery_s']} s, longest stall {med['longest_stall_s']} s "
        f"(normal gap {med['normal_gap_s']} s), rounds done {med['rounds_done']}/"
        f"{f['rounds_planned']}; identical tables {f['tables_identical_runs']}/{f['runs']} "
        f"runs, truthful verdict {f['truthful_runs']}/{f['runs']} runs"
        + (
            f"; median {med['rounds_unverified']} round(s) with a table not on record "
            "(a dead host's shares)"
            if med["rounds_unverified"]
            else ""
        )
        + f"; history clean {f.get('history_clean_runs')}/{f['runs']} runs",
    ]
    for r in f["per_run"]:
        if not r["passed"]:
            lines.append(f"  run {r['run']}: " + "; ".join(r["problems"]))
    return "\n".join(lines)


def _terminated(signum: int, frame: object) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


def cmd(args: argparse.Namespace) -> int:
    from dfrl.experiments.tools.bench import faults
    from dfrl.experiments.tools.netns import unavailable

    why = unavailable()
    if why is not None:
        print(
            f"dfrl bench faults: cannot make the simulated hosts here: {why} (the benchmark "
            "runs each host in a Linux network namespace; run it as root)",
            file=sys.stderr,
        )
        return 2

    # Ctrl-C and a kill (SIGTERM) end the benchmark through its cleanup (every lab's processes
    # killed, its namespaces deleted), also where the shell started it with SIGINT ignored
    signal.signal(signal.SIGINT, signal.default_int_handler)
    signal.signal(signal.SIGTERM, _terminated)

    def show(f: dict[str, Any]) -> None:
        print(json.dumps(f) if args.json else _text(f), flush=True)

    try:
        done = faults.run(
            args.faults,
            args.runs,
            args.hosts,
            args.keep,
            on_fault=show,
            delay_ms=args.delay_ms,
            rounds=args.rounds,
            itineraries=tuple(args.itinerary),
        )
    except ValueError as exc:
        print(f"dfrl bench faults: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(
            "dfrl bench faults: interrupted; its hosts were stopped and their namespaces removed",
            file=sys.stderr,
        )
        return 130
    return 0 if all(f["passed"] for f in done) else 1
