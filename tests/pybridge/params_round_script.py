"""Run by test_params_round.py in its own process: a dFRL agent federates two robots'
parameter vectors (issue 19).

One robot process (this one) with three platform nodes: the agent's home and one per robot;
two function learners (:class:`StaticParams`, different seeds and samples) registered with the
bridge. The real dFRL agent (``carries(params)``, ``average``) makes two rounds, hopping
between the nodes; this main thread serves the bridge like a control loop. Prints JSON.
"""

from __future__ import annotations

import faulthandler
import hashlib
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from dfrl.pybridge import Atom, Bridge, StaticParams, Term

ROOT = Path(__file__).resolve().parents[2]
AGENT = ROOT / "platform_pl" / "dfrl_agent" / "dfrl_agent.pl"
LAYOUT = [("w", (50, 20)), ("b", (20,))]
SAMPLES = {"r1": 300, "r2": 100}
ROUNDS = 2


def digest(vec: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(vec, dtype=np.float64).tobytes()).hexdigest()


def fedavg(x1: np.ndarray, w1: int, x2: np.ndarray, w2: int) -> np.ndarray:
    """What the agent computes, in its order: (w1*x1 + w2*x2) / (w1 + w2)."""
    return (w1 * x1 + w2 * x2) / (w1 + w2)


def main() -> int:
    # a hang shows where it is: every thread's Python stack on stderr, exit 1, before the
    # test's 120 s timeout (it hung once in a CI run and passed thousands of times elsewhere)
    faulthandler.dump_traceback_later(90, exit=True)
    out: dict = {}
    node = Bridge(request_timeout=10.0)
    node.load_platform()
    node.call("use_module", Atom(str(AGENT)))
    nodes = [node.start("127.0.0.1", 0, idle_timeout=1, token="test") for _ in range(3)]
    home, n1, n2 = nodes
    robots = {
        "r1": StaticParams(LAYOUT, seed=1, samples=SAMPLES["r1"]),
        "r2": StaticParams(LAYOUT, seed=2, samples=SAMPLES["r2"]),
    }
    for rid, robot in robots.items():
        node.register_robot(rid, robot, algo="dqn")
    expected = {rid: r.params for rid, r in robots.items()}
    for _ in range(ROUNDS):
        mean = fedavg(expected["r1"], SAMPLES["r1"], expected["r2"], SAMPLES["r2"])
        expected = {rid: mean for rid in robots}
    stops = [
        Term("stop", Atom(h), p, Atom(rid))
        for (h, p), rid in ((node.address(n1), "r1"), (node.address(n2), "r2"))
    ]
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "rounds.jsonl"
        plan = Term("plan", stops, ROUNDS, 0.0, Atom(str(log)), 10)
        node.call(
            "dfrl_create",
            home,
            Atom("fed_dqn"),
            plan,
            [
                Term("method", Atom("average")),
                Term("carries", Atom("params")),
                Term("tokens", ["test"]),
            ],
            module="dfrl_agent",
        )
        first = node.address(n1)
        moved = node.call("with_node", home, Term("move_agent", Atom("fed_dqn"), first))
        out["moved"] = moved is not None
        events: list[dict] = []
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            node.serve_pending(timeout=0.01)
            if log.exists():
                events = [json.loads(line) for line in log.read_text().splitlines() if line]
                if any(e["event"] == "finished" for e in events):
                    break
    out["events"] = events
    out["sets"] = {rid: r.sets for rid, r in robots.items()}
    out["digests"] = {rid: digest(r.params) for rid, r in robots.items()}
    out["expected"] = {rid: digest(v) for rid, v in expected.items()}
    out["close_left"] = [str(t) for t in node.close()]
    faulthandler.cancel_dump_traceback_later()
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
