"""Run by test_bridge_platform.py in its own process: the real platform in a robot node.

Two platform nodes in this process; an agent created on the first moves to the second,
reads the robot's table through the bridge and writes it back plus one. Prints JSON.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np
from bridge_helpers import ArrayRobot

from dfrl.pybridge import Atom, NodeStateError, Bridge, Term, Var

AGENT = Path(__file__).with_name("hop_agent.pl")


def wait_for(node: Bridge, goal: Term, timeout: float = 10.0):
    """Serve bridge requests like a control loop until goal succeeds (bindings) or timeout."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        node.serve_pending()
        sol = node.call(goal.name, *goal.args)
        if sol is not None:
            return sol
        time.sleep(0.001)
    return None


def main() -> int:
    out: dict = {}
    node = Bridge(request_timeout=10.0)
    node.load_platform()
    out["joined_none"] = node.join() is None
    # Embedded Prolog runs without signal handling, so node_stop/1 cannot interrupt a
    # connection worker blocked in a read: it ends at its idle timeout (default 10 s).
    # a token: a node without one is open and warns (the test fails on any warning)
    home = node.start("127.0.0.1", 0, idle_timeout=1, token="test")
    robot_node = node.start("127.0.0.1", 0, idle_timeout=1, token="test")
    home_host, home_port = node.address(home)
    robot_host, robot_port = node.address(robot_node)
    out["joined_home"] = node.join() == home  # the first node started is the default
    robot = ArrayRobot(100, 4, seed=9)
    before = robot.q_table
    node.register_robot("r1", robot)
    node.call("dynamic", Term("/", Atom("agent_done"), 3))
    node.call("dynamic", Term("/", Atom("got_mail"), 2))
    node.call("assertz", Term("robot_port", robot_port))
    node.assert_file_to_tartarus(AGENT)
    name = node.create_mobile_agent(None, (home_host, home_port), "hop", [])
    out["listed_before"] = [str(a) for a in node.list_agents()]
    node.execute_agent(name, (home_host, home_port), "hop")
    done = wait_for(node, Term("agent_done", Var("A"), Var("P"), Var("S")))
    out["done"] = done is not None
    if done:
        out["agent"] = str(done["A"])
        out["port_ok"] = done["P"] == robot_port
        out["sum_ok"] = bool(
            done["S"].name == "-"
            and np.isclose(done["S"].args[0], before.sum())
            and done["S"].args[1] == Atom("none")
        )
    out["table_plus_one"] = bool(np.array_equal(robot.q_table, before + 1.0))
    out["name"] = str(name)
    home_link, robot_link = (home_host, home_port), (robot_host, robot_port)

    # moved from Python, with a payload fact that travels with it
    after_first = robot.q_table
    node.create_mobile_agent("mover", home_link, "hop", [])
    node.call("assertz", Term("carried", Atom("mover"), "from python"))
    node.add_payload("mover", [("carried", 2)])
    node.move_agent("mover", robot_link)
    done = wait_for(node, Term("agent_done", Atom("mover"), Var("P"), Var("R")))
    out["moved_ok"] = bool(
        done
        and done["P"] == robot_port
        and done["R"] == Term("-", done["R"].args[0], "from python")
        and np.isclose(done["R"].args[0], after_first.sum())
        and np.array_equal(robot.q_table, after_first + 1.0)
    )

    # list and purge
    node.create_mobile_agent("idle", home_link, "hop", [])
    listed = [str(a) for a in node.list_agents()]
    node.purge_agent("idle")
    out["purge_ok"] = "idle" in listed and "idle" not in [str(a) for a in node.list_agents()]

    # a message posted to a static agent on the robot's platform
    node.create_static_agent("mbox", robot_link, "mailbox", [])
    node.execute_agent("mbox", robot_link, "mailbox")
    node.post_agent("platform", robot_link, [Atom("mailbox"), Atom("mbox"), robot_link, "hello"])
    mail = wait_for(node, Term("got_mail", Atom("mbox"), Var("T")))
    out["post_ok"] = bool(mail and mail["T"] == "hello")

    # Tartarus-style start on an OS-chosen port, with a token
    tnode = node.start_tartarus("127.0.0.1", 0, 1111)
    out["tartarus_ok"] = node.address(tnode)[1] > 0 and node.join() == tnode
    out["left"] = [str(t) for t in node.close(thread_timeout=5.0)]
    # if close() had to abort platform threads, the platform refuses to run again in this
    # process; after a clean close it runs again (and must really work)
    out["spent"] = Bridge._platform_spent
    again = Bridge()
    try:
        again.load_platform()
        out["reload"] = (
            "ran" if again.address(again.start("127.0.0.1", 0, token="test"))[1] > 0 else "broken"
        )
    except NodeStateError:
        out["reload"] = "refused"
    finally:
        again.close()
    print(json.dumps(out), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
