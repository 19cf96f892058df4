"""Node identity across processes: "is this address me?" by the id in the hello (issue 8).

Address text cannot tell: a node bound to 0.0.0.0 is reached by every name of its host, and two
hosts may use one port number. Here two processes bind the same port on 127.0.0.1 and 127.0.0.2,
and a node bound to 0.0.0.0 is reached through another loopback address and through a proxy.
"""

from __future__ import annotations

import socket
import subprocess
import time
from pathlib import Path

import pytest

from dfrl.experiments.tools.bench.fault_proxy import FaultProxy
from dfrl.platform_pl import PLATFORM_DIR

from .conftest import SWIPL, Proc, start_node
from .wire_client import connect, frame, open_proof, read_frame

pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")

TARTARUS = repr(str(PLATFORM_DIR / "tartarus.pl"))


def _node(
    procs: list[Proc], tmp_path: Path, name: str, host: str, port: int = 0
) -> tuple[Proc, int]:
    """A node process on host:port (token 7) that answers commands on stdin.

    `self(Host, Port).` prints SELF true|false (node_is_self of its node); `move(Name, Host,
    Port).` creates agent Name, which prints ARRIVED Name Port wherever it starts, and moves it.
    """
    path = tmp_path / f"{name}.pl"
    path.write_text(f"""
    :- use_module({TARTARUS}).
    :- dynamic hop/3.
    hop(guid, (_, P), main) :- format("ARRIVED ~w ~w~n", [guid, P]), flush_output.
    main :-
        node_start('{host}':{port}, N, [token(7), default(true), insecure(true)]),
        node_property(N, bind(_:P)), format("LISTENING ~w~n", [P]), flush_output,
        repeat,
        read_term(user_input, Cmd, []),
        (   Cmd == end_of_file -> !
        ;   Cmd = self(H, Pt)
        ->  ( node:node_is_self(N, H:Pt) -> R = true ; R = false ),
            format("SELF ~w~n", [R]), flush_output, fail
        ;   Cmd = move(Name, H, Pt),
            create_mobile_agent(Name, hop, [7]),
            catch(( move_agent(Name, (H, Pt)), format("MOVED ~w~n", [Name]) ), E,
                  format("FAILED ~w ~q~n", [Name, E])),
            list_agents, flush_output, fail
        ).
    """)
    proc = Proc([SWIPL, "-q", "-g", "main", str(path)])
    procs.append(proc)
    return proc, int(proc.wait_for("LISTENING").split()[1])


def _ask(proc: Proc, command: str, answer: str, timeout: float = 20.0) -> str:
    """Send a command; return the next new output line starting with ``answer``."""
    assert proc.popen.stdin is not None
    seen = sum(1 for line in list(proc.lines) if line.startswith(answer))
    proc.popen.stdin.write(command + ".\n")
    proc.popen.stdin.flush()
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        hits = [line for line in list(proc.lines) if line.startswith(answer)]
        if len(hits) > seen:
            return hits[seen]
        time.sleep(0.01)
    raise AssertionError(f"no {answer!r} after {command!r}:\n{proc.output()}")


def test_same_port_on_two_hosts_is_not_confused(tmp_path: Path, procs: list[Proc]) -> None:
    # Prepare: A on 127.0.0.1:P, B on 127.0.0.2:P, two processes.
    a, port = _node(procs, tmp_path, "a", "127.0.0.1")
    b, _ = _node(procs, tmp_path, "b", "127.0.0.2", port)
    # Execute / Assert: A is A, B is not A; an agent sent to B arrives at B.
    assert _ask(a, f"self('127.0.0.2', {port})", "SELF") == "SELF false"
    assert _ask(b, f"self(localhost, {port})", "SELF") == "SELF false"
    assert _ask(a, f"self(localhost, {port})", "SELF").startswith("SELF")
    a.popen.stdin.write(f"move(t1, '127.0.0.2', {port}).\n")
    a.popen.stdin.flush()
    a.wait_for("MOVED t1")
    b.wait_for(f"ARRIVED t1 {port}")
    assert "ARRIVED t1" not in a.output()


def test_wildcard_node_knows_itself_by_any_address(tmp_path: Path, procs: list[Proc]) -> None:
    # Prepare: a node bound to 0.0.0.0, and a proxy in front of it.
    node, port = _node(procs, tmp_path, "w", "0.0.0.0")
    with FaultProxy(("127.0.0.1", port)) as proxy:
        # Execute / Assert: itself through 127.0.0.1, its host name, 127.0.0.2 and the proxy
        # (the last two by the id in the hello); not any other node.
        for host, p in [
            ("127.0.0.1", port),
            (socket.gethostname(), port),
            ("127.0.0.2", port),
            ("127.0.0.1", proxy.address[1]),
        ]:
            assert _ask(node, f"self('{host}', {p})", "SELF") == "SELF true", (host, p)
        other, other_port = _node(procs, tmp_path, "o", "127.0.0.1")
        assert _ask(node, f"self('127.0.0.1', {other_port})", "SELF") == "SELF false"
        # An agent moved to "another" address of its own node restarts there, once, and
        # stays (binding 0.0.0.0 used to make it migrate into its own node and be lost).
        node.popen.stdin.write(f"move(t2, '127.0.0.2', {port}).\n")
        node.popen.stdin.flush()
        node.wait_for("MOVED t2")
        node.wait_for("ARRIVED t2")
        time.sleep(0.3)
        assert node.output().count("ARRIVED t2") == 1, node.output()
        assert "FAILED" not in node.output()
        assert other.output().count("ARRIVED") == 0


def test_hello_carries_id_and_idle_limits(procs: list[Proc]) -> None:
    _, port = start_node(procs, "--host", "0.0.0.0", "--advertise", "127.0.0.1", "--insecure")
    with connect(port) as s:
        s.sendall(frame(b"ping .\n"))
        assert read_frame(s) is not None
    hello = _hello(port)
    assert hello.startswith("hello(1,") and f"node('127.0.0.1',{port},[id(" in hello
    assert "idle(10)" in hello and "auth_idle(60)" in hello


def _hello(port: int) -> str:
    with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
        got = read_frame(s)
        assert got is not None
        return got[1]


def test_node_command_advertises(procs: list[Proc]) -> None:
    proc, port = start_node(
        procs, "--host", "0.0.0.0", "--advertise", "robot-3.lab:7300", "--insecure"
    )
    assert "listening on robot-3.lab:7300" in proc.output()
    assert "node('robot-3.lab',7300," in _hello(_bound_port(proc))


def _bound_port(proc: Proc) -> int:
    out = subprocess.run(["ss", "-Htlnp"], capture_output=True, text=True).stdout
    for line in out.splitlines():
        if f"pid={proc.popen.pid}," in line:
            return int(line.split()[3].rsplit(":", 1)[1])
    raise AssertionError(out)


def test_oversized_binary_frame_refused_before_its_body(procs: list[Proc]) -> None:
    # Prepare: an open node (no token) takes frames up to 32 MiB once the open key is proved.
    _, port = start_node(procs)
    with connect_with_nonce(port) as (s, nonce):
        s.sendall(frame(f"auth(['{open_proof(nonce)}']) .\n".encode()))
        reply = read_frame(s)
        assert reply is not None and reply[1].startswith("ok(authenticated)"), reply
        # Execute: a binary header claiming 300 MiB, and no body.
        s.sendall(frame(b"", kind=b"B", length=300 * 2**20))
        reply = read_frame(s)
    # Assert: refused at once, by size.
    assert reply is not None and "too_large(314572800,33554432)" in reply[1], reply


class connect_with_nonce:  # noqa: N801 (a context manager used like a function)
    """Connect, read the hello and give (socket, nonce)."""

    def __init__(self, port: int) -> None:
        self.sock = socket.create_connection(("127.0.0.1", port), timeout=5)

    def __enter__(self) -> tuple[socket.socket, str]:
        hello = read_frame(self.sock)
        assert hello is not None
        nonce = hello[1].split(",")[1].strip("'")
        return self.sock, nonce

    def __exit__(self, *exc: object) -> None:
        self.sock.close()
