"""The console is not on the agent's critical path (issue 33): its round-log lines go through
the outbox of the node it is on (``platform_pl/dfrl_agent/log_outbox.pl``).

Real processes on loopback: four stop processes (``test_resting_holder``'s node with a kept
log each, ``outbox_configure/2``) and a console node (``dfrl_console.pl``, the driver's) that
launched the agent with ``log_to`` itself. The console is frozen with ``SIGSTOP`` after round
2 for longer than a round takes: the agent's rounds go on at their pace (before, each line
waited for the console's reply, up to the stops' reply timeout), the lines are in the stops'
kept logs, and after ``SIGCONT`` every one reaches the console's file, each once as read
(:func:`read_rounds_log` drops a line posted twice).
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest

from dfrl.experiments.driver.console.node import ConsoleNode
from dfrl.experiments.driver.results.agent_log import AgentLog, kept_logs, read_rounds_log

from .conftest import SWIPL, Proc
from .test_resting_holder import NODE, TOKEN
from .tour import Tour

pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")

ROUNDS = 10
REST_S = 0.3
REPLY_S = 4.0  # the stops' reply timeout: what one line cost before, per line
FROZEN_S = 5.0

#: the stop of test_resting_holder, keeping its lines in KEEP/<robot>
KEEPING = NODE.replace("node_start(localhost:Port, _,", "node_start(localhost:Port, Node,").replace(
    '    format("LISTENING',
    "    getenv('KEEP', Keep), directory_file_path(Keep, Robot, "
    "Dir),\n    log_outbox:outbox_configure(Node, [keep_dir(Dir)]),\n"
    '    format("LISTENING',
)


class KeepingStops(Tour):
    """Stops r0..r(n-1), each keeping its round-log lines in ``tmp/agent_logs/r<i>``."""

    def __init__(self, tmp_path: Path, procs: list[Proc], n: int) -> None:
        super().__init__(tmp_path, procs, n, TOKEN)
        (tmp_path / "node.pl").write_text(KEEPING)
        env = {**os.environ, "KEEP": str(tmp_path / "agent_logs")}
        self.nodes = [
            Proc(
                [
                    SWIPL,
                    "-q",
                    "-g",
                    "main",
                    str(tmp_path / "node.pl"),
                    str(self.ports[i]),
                    f"r{i}",
                    f"{float(i)}",
                    "0.0",
                    "1.5",
                    str(REPLY_S),
                    "new",
                    "none",
                ],
                env=env,
            )
            for i in range(n)
        ]
        procs.extend(self.nodes)
        for p in self.nodes:
            p.wait_for("LISTENING")


def read_kept(tmp_path: Path) -> AgentLog:
    """The stops' kept logs of agent fx, merged (each line once)."""
    return read_rounds_log(tmp_path / "no-console.log", "fx", kept=kept_logs(tmp_path, "fx"))


def test_frozen_console_does_not_stop_the_rounds(tmp_path: Path, procs: list[Proc]) -> None:
    # Prepare: four stops keeping their lines; the console that launches the agent and
    # appends its lines to driver/rounds_fx.log
    stops = KeepingStops(tmp_path, procs, 4)
    drv = tmp_path / "driver"
    drv.mkdir()
    log = drv / "rounds_fx.log"
    console = ConsoleNode(tokens=TOKEN, log_path=tmp_path / "console.err")
    try:
        host, port = console.address
        console.launch_agent(
            {
                "name": "fx",
                "rounds": ROUNDS,
                "rest_s": REST_S,
                "rounds_log": str(log),
                "log_to": [host, port],
                "itinerary": [
                    {"host": "localhost", "port": p, "robot": f"r{i}"}
                    for i, p in enumerate(stops.ports)
                ],
            }
        )
        stops.log = log
        stops.wait(lambda: len(read_rounds_log(log, "fx").rounds) >= 2, 30, "round 2")
        # Execute: freeze the console; the rounds go on meanwhile
        os.kill(console.pid, signal.SIGSTOP)
        frozen = time.time()
        try:
            time.sleep(FROZEN_S)
            during = [r for r in read_kept(tmp_path).rounds if r.end > frozen]
            in_file = len(read_rounds_log(log, "fx").rounds)
        finally:
            os.kill(console.pid, signal.SIGCONT)
        # the lines kept while frozen reach the console once it answers
        stops.wait(
            lambda: read_rounds_log(log, "fx").finished is not None,
            60,
            "the finished line in the console's file",
        )
        whole = read_rounds_log(log, "fx")
        kept = read_kept(tmp_path)
    finally:
        console.close()
    # Assert: while the console was frozen the agent ran rounds at its pace (more than two in
    # 5 s; before, a round's line cost the 4 s reply timeout) and the console's file had
    # none of them; after SIGCONT every round is in its file once and equals the kept lines
    assert len(during) >= 3, [r.round for r in during]
    gaps = [b.end - a.end for a, b in zip(during, during[1:])]
    assert max(gaps) < REPLY_S, gaps
    assert in_file <= 3, in_file
    assert [r.round for r in whole.rounds] == list(range(1, ROUNDS + 1))
    assert whole.duplicates == [] and whole.unreadable == []
    assert whole.rounds == kept.rounds
    raw = [line for line in log.read_text().splitlines() if line.strip()]
    assert len(set(raw)) == len(whole.rounds) + 1  # + finished
