"""The namespace lab itself: hosts reach each other over TCP, a cut link stops that, and
closing the lab leaves no namespace behind."""

from __future__ import annotations

import sys
from pathlib import Path

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
WRITE = """
import pathlib, sys
p = pathlib.Path(sys.argv[1]); p.parent.mkdir(parents=True); p.write_text('round,end\\n')
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
        server = b.popen(
            [sys.executable, "-c", ECHO_SERVER, b.address], stdout=subprocess.PIPE, text=True
        )
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


def test_private_disks_a_file_of_the_driver_is_not_on_a_robot_host(tmp_path: Path) -> None:
    # Prepare: a lab whose hosts each see a tmpfs of their own over tmp_path
    with Lab(["h1", "driver"], private=tmp_path) as lab:
        drv, h1 = lab["driver"], lab["h1"]
        secret = tmp_path / "driver" / "out" / "rounds.csv"
        # Execute: the driver writes a file from inside its host
        made = drv.run([sys.executable, "-c", WRITE, str(secret)], capture_output=True, text=True)
        assert made.returncode == 0, made.stderr
        # Assert: the driver reads it back; the robot host and the machine do not see it
        seen = drv.run(["cat", str(secret)], capture_output=True, text=True)
        assert seen.stdout == "round,end\n"
        absent = h1.run(["ls", "-A", str(tmp_path)], capture_output=True, text=True)
        assert absent.returncode == 0 and absent.stdout == "", absent
        assert h1.run(["test", "-e", str(secret)]).returncode == 1
        assert not secret.exists() and list(tmp_path.iterdir()) == []
        # the lab's maker reads it through the driver's view, from no shared folder
        assert drv.view(secret).read_text() == "round,end\n"
        assert not h1.view(secret).exists()
        # a working directory is a path of the host's own disk; a killed host keeps its disk
        (h1.view(tmp_path) / "h1").mkdir()
        here = h1.run(["pwd"], cwd=tmp_path / "h1", capture_output=True, text=True)
        assert here.stdout.strip() == str(tmp_path / "h1")
        lab.kill("driver")
        assert drv.view(secret).read_text() == "round,end\n"
        keepers = [lab[h].keeper for h in ("h1", "driver")]
        tag = lab.tag
    assert all(k is not None and k.poll() is not None for k in keepers)
    assert not leftover_namespaces(tag)
