"""``dfrl bench ...``: benchmarks that print their figures (JSON with ``--json``).

Each benchmark is a module with ``add_arguments(parser)`` and ``run_cli(args) -> int``
(or ``run(args) -> int``).
"""
from __future__ import annotations

import argparse
import importlib

#: benchmark name -> module implementing it
BENCHMARKS: dict[str, str] = {
    "migrate": "dfrl.experiments.bench_migrate",
    "sim": "dfrl.experiments.bench_sim",
    "round": "dfrl.experiments.bench_round",
    "bridge": "dfrl.experiments.bench_bridge",
}


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``bench`` and one sub-command per available benchmark."""
    parser = subparsers.add_parser("bench", help="run a benchmark and print its figures")
    inner = parser.add_subparsers(dest="benchmark", metavar="BENCHMARK", required=True)
    for name, module_name in BENCHMARKS.items():
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:
            if exc.name == module_name:
                continue  # not built yet
            raise
        sub = inner.add_parser(name, help=(module.__doc__ or "").strip().splitlines()[0])
        module.add_arguments(sub)
        sub.set_defaults(func=getattr(module, "run_cli", None) or module.run)
