"""Time an agent's ``get_params/3`` + ``set_params/3`` through the bridge (issue 19).

An agent-like Prolog thread (``bridge_bench.pl``) reads a :class:`StaticParams` robot's
vector and writes it back, ``repeats`` times, while this main thread serves the requests like
an idle control loop; the same for a Q-table of the same number of floats, for comparison.
Prints one JSON object per size::

    python -m dfrl.pybridge.params_bench --floats 10000 100000 --repeats 30
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

BENCH_FILE = Path(__file__).resolve().parent / "bridge_bench.pl"


def _stats(values: list[float]) -> dict[str, float]:
    arr = np.asarray(values, dtype=np.float64)
    return {
        "median_ms": round(float(np.median(arr)), 3),
        "p90_ms": round(float(np.percentile(arr, 90)), 3),
    }


def time_pairs(node: Any, what: str, robot: str, warmup: int, repeats: int) -> dict[str, Any]:
    """Run the agent thread for ``what`` (``"params"`` or ``"table"``) on ``robot`` and serve
    it until it is done; medians and p90 of read+write, read and write (ms)."""
    from dfrl.pybridge import Atom, Term, Var

    goal = Term(f"bench_{what}_round_trips", Atom(robot), warmup, repeats, [])
    node.call(
        "thread_create",
        goal,
        Var(),
        [Term("alias", Atom(f"bench_{what}")), Term("detached", Atom("true"))],
        module="bridge_bench",
    )
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:
        if node.serve_pending(timeout=0.005):
            continue
        sol = node.call("bench_result", Var("R"), module="bridge_bench")
        if sol is not None:
            result = sol["R"]
            if result.name == "error":
                raise RuntimeError(f"the benchmark agent failed: {result.args[0]!r}")
            totals, gets, sets = (list(x) for x in result.args)
            return {
                "pair": _stats(totals),
                "get": _stats(gets),
                "set": _stats(sets),
                "pairs": len(totals),
            }
    raise RuntimeError("the benchmark agent did not finish in 300 s")


def bench(floats: list[int], repeats: int = 30, warmup: int = 3) -> list[dict[str, Any]]:
    """One row per size: params and table timings, and whether the vector came back bit
    for bit."""
    from dfrl.pybridge import Atom, Bridge, StaticParams, StaticTable

    rows = []
    with Bridge(request_timeout=60.0) as node:
        node.call("use_module", Atom(str(BENCH_FILE)))
        for n in floats:
            params = StaticParams([("w", (n,))], seed=n, samples=1)
            node.register_robot("p", params)
            table = StaticTable((n // 4, 4), seed=n)
            node.register_robot("t", table, shape=(n // 4, 4))
            before = params.params
            row: dict[str, Any] = {"floats": n, "codec": node.codec.value}
            row["params"] = time_pairs(node, "params", "p", warmup, repeats)
            row["params"]["bit_exact"] = bool(
                np.array_equal(params.params.view(np.int64), before.view(np.int64))
            )
            row["table"] = time_pairs(node, "table", "t", warmup, repeats)
            rows.append(row)
            node.unregister_robot("p")
            node.unregister_robot("t")
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--floats", type=int, nargs="+", default=[10000, 100000])
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--warmup", type=int, default=3)
    args = parser.parse_args(argv)
    if any(n < 4 or n % 4 for n in args.floats):
        parser.error("--floats: multiples of 4, at least 4 (the table has 4 actions)")
    for row in bench(args.floats, args.repeats, args.warmup):
        print(json.dumps(row))
    return 0


if __name__ == "__main__":
    sys.exit(main())
