"""Run in a subprocess by test_bridge_exit.py: a node with busy agent threads, then exit.

usage: exit_script.py MODE   (MODE: atexit | close | serving | raise)
Prints "READY" once the agents run; the exit code and stderr tell whether shutdown was clean.
"""

from __future__ import annotations

import sys
import time

from bridge_helpers import HELPER, ArrayRobot

from dfrl.pybridge import Atom, Bridge, Term, Var


def main(mode: str) -> int:
    node = Bridge(request_timeout=60.0)
    node.call("use_module", Atom(str(HELPER)))
    robot = ArrayRobot(2000, 10)
    node.register_robot("r1", robot)
    loop = Term(
        "forall",
        Term("between", 1, 1000000, Var()),
        Term(
            ",", Term("get_qtable", Atom("r1"), Var("T")), Term("set_qtable", Atom("r1"), Var("T"))
        ),
    )
    for i in range(3):
        node.call("spawn", Atom(f"busy_{i}"), loop, module="bridge_test_agents")
    spin = Term("forall", Term("between", 1, 100000000, Var()), Atom("true"))
    node.call("spawn", Atom("spinner"), spin, module="bridge_test_agents")
    node.call(
        "spawn", Atom("sleeper"), Term("thread_get_message", Var()), module="bridge_test_agents"
    )
    deadline = time.monotonic() + 0.5
    served = 0
    while time.monotonic() < deadline:
        served += node.serve_pending()
    print("READY", served, flush=True)
    if mode == "close":
        left = node.close()
        print("LEFT", left, flush=True)
    elif mode == "raise":
        raise SystemExit(3)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
