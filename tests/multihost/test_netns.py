"""The namespace lab itself: hosts reach each other over TCP, a cut link stops that, and
closing the lab leaves no namespace behind."""
from __future__ import annotations

import sys

import pytest

from dfrl.experiments.tools.netns import Lab, leftover_namespaces, unavailable

WHY = unavailable()
pytestmark = pytest.mark.skipif(WHY is not None, reason=WHY or "")

ECHO_SERVER = """
import socket, sys
s = socket.socket(); s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
s.bind((sys.argv[1], 7100)); s.listen(); print('up', flush=True)
for _ in range(10):
    c, _ = s.accept(); c.sendall(c.recv(100).upper()); c.close()
"""
CLIENT = """
import socket, sys
try:
    with socket.create_connection((sys.argv[1], 7100), timeout=2) as c:
        c.sendall(b'hello'); print(c.recv(100).decode())
except OSError as e:
    print('ERR', type(e).__name__)
"""


def test_hosts_talk_and_a_cut_link_separates_them() -> None:
    import subprocess

    with Lab(["a", "b"]) as lab:
        a, b = lab["a"], lab["b"]
        server = b.popen([sys.executable, "-c", ECHO_SERVER, b.address],
                         stdout=subprocess.PIPE, text=True)
        assert server.stdout is not None and server.stdout.readline().strip() == "up"
        out = a.run([sys.executable, "-c", CLIENT, b.address], capture_output=True, text=True)
        assert out.stdout.strip() == "HELLO"
        # the host's own namespace does not see the machine's loopback services
        lab.cut("b")
        out = a.run([sys.executable, "-c", CLIENT, b.address], capture_output=True, text=True)
        assert out.stdout.startswith("ERR")
        lab.mend("b")
        out = a.run([sys.executable, "-c", CLIENT, b.address], capture_output=True, text=True)
        assert out.stdout.strip() == "HELLO"
        tag = lab.tag
    assert not leftover_namespaces(tag)
