""" "Is this address me?" asks no other host (issue 20).

A mover asks it twice a hop. It used to connect to the address to read the id in its hello
once the last hello seen there was a minute old; a stop cut off for longer then cost each try
up to two connect timeouts beyond the skip time (rounds of 19 s in `dfrl bench faults`
cut_90s). Only an address of this host can reach a node of this process, and the kernel says
which those are when a socket binds, so a remote address is now answered without a packet.
"""

from __future__ import annotations

import subprocess
import sys
import threading
import time

import pytest

from dfrl.experiments.tools.netns import Lab, unavailable
from dfrl.platform_pl import PLATFORM_DIR
from dfrl.experiments.processes import find_swipl

WHY = unavailable()
SWIPL = find_swipl()
pytestmark = [
    pytest.mark.skipif(WHY is not None, reason=WHY or ""),
    pytest.mark.skipif(SWIPL is None, reason="swipl not installed"),
]

#: Counts the connections it accepts on port 7001, one line each.
COUNTER = """
import socket, sys
s = socket.socket(); s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
s.bind((sys.argv[1], 7001)); s.listen(); print('up', flush=True)
for _ in range(20):
    c, _ = s.accept(); print('accepted', flush=True); c.close()
"""

#: A node bound to 0.0.0.0:7001; `self(Host).` prints SELF true|false and the time taken,
#: `touch(Host).` makes one plain TCP connection to Host:7001 (the counter's control).
NODE = f"""
:- use_module({str(PLATFORM_DIR / "tartarus.pl")!r}).
:- use_module(library(socket)).
main :-
    node_start('0.0.0.0':7001, N, [token(7), default(true), insecure(true)]),
    format("LISTENING~n"), flush_output,
    repeat,
    read_term(user_input, Cmd, []),
    (   Cmd == end_of_file -> !
    ;   Cmd = self(H)
    ->  get_time(T0),
        ( node:node_is_self(N, H:7001) -> R = true ; R = false ),
        get_time(T1), Ms is (T1 - T0) * 1000,
        format("SELF ~w ~3f~n", [R, Ms]), flush_output, fail
    ;   Cmd = touch(H)
    ->  catch(( tcp_connect(H:7001, S, []), close(S), format("TOUCHED~n") ), E,
              format("TOUCH FAILED ~q~n", [E])),
        flush_output, fail
    ).
"""


class Node:
    def __init__(self, popen: subprocess.Popen) -> None:
        self.popen = popen
        self.wait_for("LISTENING")

    def wait_for(self, prefix: str, timeout: float = 20.0) -> str:
        assert self.popen.stdout is not None
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            line = self.popen.stdout.readline()
            if not line:
                break
            if line.startswith(prefix):
                return line.strip()
        raise AssertionError(f"no {prefix!r} from the node")

    def ask(self, command: str, prefix: str) -> str:
        assert self.popen.stdin is not None
        self.popen.stdin.write(command + ".\n")
        self.popen.stdin.flush()
        return self.wait_for(prefix)


def _self(node: Node, host: str) -> tuple[bool, float]:
    _, answer, ms = node.ask(f"self('{host}')", "SELF").split()
    return answer == "true", float(ms)


def test_a_remote_address_is_not_self_without_a_connection(tmp_path) -> None:
    with Lab(["a", "b"]) as lab:
        a, b = lab["a"], lab["b"]
        counter = b.popen(
            [sys.executable, "-c", COUNTER, b.address], stdout=subprocess.PIPE, text=True
        )
        assert counter.stdout is not None and counter.stdout.readline().strip() == "up"
        accepted: list[str] = []
        threading.Thread(target=lambda: accepted.extend(counter.stdout), daemon=True).start()
        script = tmp_path / "node.pl"
        script.write_text(NODE)
        node = Node(
            a.popen(
                [SWIPL, "-q", "-g", "main", str(script)],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.DEVNULL,
                text=True,
            )
        )
        # Execute / Assert: b's address is not the node, and b saw no connection for it.
        is_self, ms = _self(node, b.address)
        assert not is_self
        assert ms < 100, ms
        # Control: the counter does see a connection from a (so its count counts).
        assert node.ask(f"touch('{b.address}')", "TOUCH") == "TOUCHED"
        deadline = time.monotonic() + 10
        while not accepted and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(0.2)
        assert accepted == ["accepted\n"], accepted
        # Control: a's own address, which is no literal name of a node bound to 0.0.0.0, is
        # still recognised by the id in its hello (the local path still asks).
        assert _self(node, a.address)[0]
        # Execute / Assert: with b cut off, the answer is as quick (it used to take a connect
        # timeout once the last hello seen from b was a minute old).
        lab.cut("b")
        is_self, ms = _self(node, b.address)
        assert not is_self
        assert ms < 100, ms
        node.popen.stdin.close()
        node.popen.wait(timeout=20)
