"""The console node (dfrl_console.pl) and its Python driver, with real swipl processes."""

from __future__ import annotations

import json
import socket
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from dfrl.experiments.driver.console import CONSOLE_SCRIPT, ConsoleNode
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.tokens import env_with_tokens
from dfrl.platform_pl import DFRL_AGENT_DIR, PLATFORM_DIR
from dfrl.experiments.processes import find_swipl

SWIPL = find_swipl()
pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")

ROBOTS = Path(__file__).with_name("control_robots.pl")
TOKEN = 7


class Node:
    """A plain platform node (node_main.pl) hosting the in-memory robots r1..r4."""

    def __init__(self, consult: Path = ROBOTS) -> None:
        assert SWIPL is not None
        self.proc = subprocess.Popen(
            [
                SWIPL,
                "-q",
                str(PLATFORM_DIR / "node_main.pl"),
                "--host",
                "127.0.0.1",
                "--token",
                str(TOKEN),
                "--consult",
                str(DFRL_AGENT_DIR / "dfrl_agent.pl"),
                "--consult",
                str(consult),
            ],
            stdin=subprocess.DEVNULL,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        assert self.proc.stdout is not None
        self.lines: list[str] = []
        first = self.proc.stdout.readline()  # bounded: the node prints it or exits
        while first.startswith("Warning:"):  # e.g. a Tartarus-style token on loopback
            self.lines.append(first)
            first = self.proc.stdout.readline()
        self.lines.append(first)
        if "listening on" not in first:
            self.proc.kill()
            raise AssertionError(f"node did not start: {first!r} {self.proc.stdout.read()}")
        self.port = int(first.rsplit(":", 1)[1])
        self._t = threading.Thread(target=self._drain, daemon=True)
        self._t.start()

    def _drain(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line)

    @property
    def address(self) -> tuple[str, int]:
        return ("127.0.0.1", self.port)

    def stop(self) -> None:
        self.proc.kill()
        self.proc.wait(timeout=10)


@pytest.fixture
def nodes() -> Iterator[Callable[[], Node]]:
    started: list[Node] = []

    def start() -> Node:
        n = Node()
        started.append(n)
        return n

    yield start
    for n in started:
        n.stop()


@pytest.fixture
def console() -> Iterator[ConsoleNode]:
    c = ConsoleNode(tokens=TOKEN)
    yield c
    c.close()


def log_events(path: Path) -> list[dict[str, Any]]:
    if not path.exists():
        return []
    lines = path.read_text(encoding="utf-8").splitlines()
    return [json.loads(line) for line in lines if line.strip()]


def wait_until(what: str, cond: Callable[[], Any], timeout_s: float = 20.0) -> Any:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        value = cond()
        if value:
            return value
        time.sleep(0.05)
    raise AssertionError(f"timed out waiting for {what}")


def plan(
    name: str, stops: list[tuple[Node, str]], log: Path, rounds: int = 10_000, rest_s: float = 0.05
) -> dict[str, Any]:
    return {
        "name": name,
        "method": "average",
        "rounds": rounds,
        "rest_s": rest_s,
        "rounds_log": str(log),
        "token": TOKEN,
        "timeout_s": 10,
        "itinerary": [{"host": "127.0.0.1", "port": n.port, "robot": r} for n, r in stops],
    }


def test_console_starts_and_reports_its_address() -> None:
    with ConsoleNode(tokens=[TOKEN, "secret"]) as c:
        host, port = c.address
        assert host == "127.0.0.1" and port > 0
        with socket.create_connection((host, port), timeout=5):
            pass  # it listens there
        assert c.running
    assert not c.running


def test_console_on_a_taken_port_fails_with_the_reason(console: ConsoleNode) -> None:
    with pytest.raises(ExperimentError, match="exited before it was ready") as err:
        ConsoleNode(port=console.address[1], ready_timeout_s=20)
    assert "exit code 1" in str(err.value) and "already in use" in str(err.value)


def test_bad_requests_get_error_replies_and_the_node_keeps_serving() -> None:
    # Prepare: the console script driven by hand, line by line.
    assert SWIPL is not None
    proc = subprocess.Popen(
        [SWIPL, "-q", str(CONSOLE_SCRIPT)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert proc.stdin is not None and proc.stdout is not None
    try:
        ready = json.loads(proc.stdout.readline())
        assert ready["event"] == "ready"
        own = [ready["host"], ready["port"]]
        requests = [
            "this is not json",
            "[1, 2]",
            '{"id": 1}',
            '{"id": 2, "op": "nope"}',
            '{"id": 3, "op": "control", "agent": "a", "host": "127.0.0.1", '
            '"port": 1, "command": {"bogus": 1}}',
            '{"id": 4, "op": "launch", "plan": {"itinerary": []}}',
            json.dumps({"id": 5, "op": "agents", "node": own}),
        ]
        # Execute
        for r in requests:
            proc.stdin.write(r + "\n")
        proc.stdin.flush()
        replies = [json.loads(proc.stdout.readline()) for _ in requests]
        proc.stdin.close()  # end of input: clean exit
        code = proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
    # Assert
    assert [r["id"] for r in replies] == [None, None, 1, 2, 3, 4, 5]
    assert all(r["ok"] is False and r["error"] for r in replies[:-1])
    assert "op" in replies[2]["error"]
    assert "console_op" in replies[3]["error"]
    assert "dfrl_command" in replies[4]["error"]
    assert "non_empty_itinerary" in replies[5]["error"]
    assert replies[6] == {"id": 5, "ok": True, "agents": []}
    assert code == 0


def test_errors_raise_with_the_node_text(console: ConsoleNode, tmp_path: Path) -> None:
    with pytest.raises(ExperimentError, match="cannot connect"):
        console.control(("127.0.0.1", 1), "a", {"stop": True})
    with pytest.raises(ExperimentError, match="does not exist"):
        console.load_program(tmp_path / "missing.pl", [console.address])
    assert console.agents_at(console.address) == []  # still serving


def test_launch_moves_the_agent_to_its_first_stop(
    console: ConsoleNode, nodes: Callable[[], Node], tmp_path: Path
) -> None:
    a = nodes()
    log = tmp_path / "rounds.log"
    got = console.launch_agent(plan("fed_test", [(a, "r1")], log, rest_s=0.2))
    assert got == {"agent": "fed_test", "host": "127.0.0.1", "port": a.port}
    names = wait_until(
        "the agent at its first stop", lambda: [x["name"] for x in console.agents_at(a.address)]
    )
    assert names == ["fed_test"]
    assert console.agents_at(console.address) == []  # it left the console
    with pytest.raises(ExperimentError, match="permission to create agent `fed_test"):
        console.launch_agent(plan("fed_test", [(a, "r1")], log))


def test_control_reaches_a_running_agent(
    console: ConsoleNode, nodes: Callable[[], Node], tmp_path: Path
) -> None:
    # Prepare: an agent on two nodes, resting between rounds; a third node to join.
    a, b, c = nodes(), nodes(), nodes()
    log = tmp_path / "rounds.log"
    console.launch_agent(plan("fed_test", [(a, "r1"), (b, "r2")], log))

    def rounds() -> list[dict[str, Any]]:
        return [e for e in log_events(log) if e["event"] == "round"]

    def control(command: str) -> dict[str, Any] | None:
        return next(
            (e for e in log_events(log) if e["event"] == "control" and e["command"] == command),
            None,
        )

    wait_until("a first round", rounds)
    # Execute and assert: method, an unknown method, join, another agent's stop, stop.
    console.control(a.address, "fed_test", {"method": "max"})
    assert wait_until("method applied", lambda: control("method(max)"))["status"] == "applied"
    wait_until("a max round", lambda: any(r["method"] == "max" for r in rounds()))
    console.control(a.address, "fed_test", {"method": "nonesuch"})
    ignored = wait_until("unknown method ignored", lambda: control("method(nonesuch)"))
    assert ignored["status"] == "ignored" and ignored["reason"]
    console.control(
        a.address, "fed_test", {"join": {"host": "127.0.0.1", "port": c.port, "robot": "r3"}}
    )
    wait_until(
        "a round visiting r3", lambda: any(r["visited"] == ["r1", "r2", "r3"] for r in rounds())
    )
    assert all(r["method"] == "max" for r in rounds()[-1:])
    console.control(a.address, "someone_else", {"stop": True})
    n = len(rounds())
    wait_until("rounds go on", lambda: len(rounds()) >= n + 3)
    assert not any(e["event"] == "finished" for e in log_events(log))
    console.control(a.address, "fed_test", {"stop": True})
    finished = wait_until(
        "finished", lambda: [e for e in log_events(log) if e["event"] == "finished"]
    )
    assert finished[0]["agent"] == "fed_test"
    wait_until("the agent gone", lambda: console.agents_at(a.address) == [])


def test_program_loaded_then_selected(
    console: ConsoleNode, nodes: Callable[[], Node], tmp_path: Path
) -> None:
    a, b = nodes(), nodes()
    log = tmp_path / "rounds.log"
    console.launch_agent(plan("fed_test", [(a, "r1"), (b, "r2")], log))
    got = console.load_program(
        DFRL_AGENT_DIR / "examples" / "median_method.pl", [a.address, b.address]
    )
    assert got["loaded"] == [list(a.address), list(b.address)]
    console.control(a.address, "fed_test", {"method": "median"})
    wait_until(
        "a median round",
        lambda: any(e["event"] == "round" and e["method"] == "median" for e in log_events(log)),
    )
    console.control(a.address, "fed_test", {"stop": True})
    wait_until("finished", lambda: any(e["event"] == "finished" for e in log_events(log)))


def test_join_request_reaches_the_driver_and_its_reply_comes_back() -> None:
    with ConsoleNode(tokens=TOKEN) as driver, ConsoleNode(tokens=TOKEN) as joiner:
        answers: list[dict[str, Any]] = []

        def serve(result: dict[str, Any]) -> None:
            event = driver.next_event(timeout_s=20)
            assert event is not None
            answers.append(event)
            driver.reply(tuple(event["from"]), event["request"], result)

        spec = {"id": "r9", "arena": "open", "algo": "qlearning", "seed": None}
        # Execute: one accepted, one refused request.
        t = threading.Thread(target=serve, args=({"robot": "r9", "port": 7009},))
        t.start()
        result = joiner.request_join(driver.address, spec, iterations=50, timeout_s=20)
        t.join(timeout=20)
        t = threading.Thread(target=serve, args=({"error": "robot r9 exists"},))
        t.start()
        with pytest.raises(ExperimentError, match="robot r9 exists"):
            joiner.request_join(driver.address, spec, timeout_s=20)
        t.join(timeout=20)
        # Assert
        assert result == {"robot": "r9", "port": 7009}
        first = answers[0]
        assert first["event"] == "join_request"
        assert first["robot"] == spec and first["iterations"] == 50
        assert first["from"] == list(joiner.address)
        assert answers[1]["iterations"] is None
        assert driver.events() == [] and joiner.events() == []


def test_join_request_without_answer_times_out() -> None:
    with ConsoleNode() as driver, ConsoleNode() as joiner:
        t0 = time.monotonic()
        with pytest.raises(ExperimentError, match="no answer"):
            joiner.request_join(driver.address, {"id": "r9"}, timeout_s=1.0)
        assert time.monotonic() - t0 < 5
        event = driver.next_event(timeout_s=5)
        assert event is not None and event["event"] == "join_request"


def test_one_shot_scripts_launch_and_control(nodes: Callable[[], Node], tmp_path: Path) -> None:
    # dfrl_launch.pl and dfrl_control.pl, one swipl per launch or command, still work.
    assert SWIPL is not None
    a = nodes()
    log = tmp_path / "rounds.log"
    launch = tmp_path / "launch.json"
    launch.write_text(json.dumps(plan("fed_test", [(a, "r1")], log)), encoding="utf-8")
    out = subprocess.run(
        [SWIPL, "-q", str(DFRL_AGENT_DIR / "dfrl_launch.pl"), str(launch)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 0, out.stderr
    assert f"DFRL_AGENT fed_test launched to 127.0.0.1:{a.port}" in out.stdout
    wait_until("a first round", lambda: any(e["event"] == "round" for e in log_events(log)))
    command = tmp_path / "command.json"

    def control(doc: dict[str, Any]) -> subprocess.CompletedProcess[str]:
        command.write_text(json.dumps(doc), encoding="utf-8")
        return subprocess.run(
            [
                SWIPL,
                "-q",
                str(DFRL_AGENT_DIR / "dfrl_control.pl"),
                "127.0.0.1",
                str(a.port),
                str(command),
            ],
            env=env_with_tokens([TOKEN]),
            capture_output=True,
            text=True,
            timeout=60,
        )

    refused = control({"stop": True})  # no agent named: refused
    assert refused.returncode == 1 and "agent" in refused.stderr
    program = str(DFRL_AGENT_DIR / "examples" / "median_method.pl")
    sent = control(
        {
            "agent": "fed_test",
            "method": "median",
            "program": program,
            "nodes": [["127.0.0.1", a.port]],
        }
    )
    assert sent.returncode == 0, sent.stderr
    wait_until(
        "a median round",
        lambda: any(e["event"] == "round" and e["method"] == "median" for e in log_events(log)),
    )
    assert control({"agent": "fed_test", "stop": True}).returncode == 0
    wait_until("finished", lambda: any(e["event"] == "finished" for e in log_events(log)))


ROBOT_PEER = Path(__file__).parent / "launcher" / "robot_peer.pl"


def test_robot_op_sends_k5_requests_and_converts_the_answers() -> None:
    import base64

    peer = Node(consult=ROBOT_PEER)
    try:
        with ConsoleNode(tokens=TOKEN) as c:
            status = c.robot(peer.address, "status")
            assert status["state"] == "idle" and status["robot"] == "r1"
            assert status["iteration"] == 7 and status["error"] is None
            assert c.robot(peer.address, {"configure": json.dumps({"experiment": "e"})}) is True
            assert c.robot(peer.address, "status")["state"] == "configured"
            assert c.robot(peer.address, "start") is True
            files = c.robot(peer.address, "files")
            assert files == [{"name": "metrics_r1.csv", "size": 26}]
            data, offset = b"", 0
            for _ in range(20):
                chunk = c.robot(
                    peer.address, {"fetch": {"name": "metrics_r1.csv", "offset": offset, "max": 10}}
                )
                part = base64.b64decode(chunk["data"])
                data += part
                offset += len(part)
                if chunk["eof"]:
                    break
            assert data == b"robot,iteration\nr1,1\nr1,2\n"
            with pytest.raises(ExperimentError, match="robot_request"):
                c.robot(peer.address, {"reboot": True})
            with pytest.raises(ExperimentError, match="robot_request"):
                c.robot(peer.address, {"fetch": {"name": "nope", "offset": 0, "max": 1}})
        with ConsoleNode(tokens=12345) as wrong:  # a token the peer does not know
            with pytest.raises(ExperimentError):
                wrong.robot(peer.address, "status")
    finally:
        peer.stop()


def test_robot_op_to_a_dead_address_fails_without_blocking_the_console(
    console: ConsoleNode,
) -> None:
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        dead = ("127.0.0.1", s.getsockname()[1])
    with pytest.raises(ExperimentError, match="robot failed"):
        console.robot(dead, "status", timeout_s=5)
    assert console.agents_at(console.address) == []


def test_launch_with_its_first_stop_down_starts_at_the_next(
    console: ConsoleNode, nodes: Callable[[], Node], tmp_path: Path
) -> None:
    # Prepare: the first stop is a node that was started and killed (nothing listens there).
    dead, b = nodes(), nodes()
    dead.proc.kill()
    dead.proc.wait(timeout=10)
    log = tmp_path / "rounds.log"
    # Execute
    got = console.launch_agent(plan("fed_test", [(dead, "r1"), (b, "r2")], log, rounds=3))
    # Assert: the launch says what happened, the agent re-homes at r2 and runs its rounds,
    # each reporting the dead stop as skipped.
    assert got["first_stop_failed"], got
    done = wait_until("finished", lambda: [e for e in log_events(log) if e["event"] == "finished"])
    assert done[0]["round"] == 3
    rounds = [e for e in log_events(log) if e["event"] == "round"]
    assert [r["round"] for r in rounds] == [1, 2, 3]
    assert all(r["visited"] == ["r2"] for r in rounds)
    assert all(s["robot"] == "r1" for r in rounds for s in r["skipped"])
