"""The slow link of ``dfrl bench faults --delay-ms``: a real proxy process inside a network
namespace in front of a server on that host's loopback, timed from another host (control: the
same exchange without the delay), and the bounds it stretches."""

from __future__ import annotations

import subprocess
import sys

import pytest

from dfrl.experiments.tools.bench import faults
from dfrl.experiments.tools.bench.faults_cases import Expectation
from dfrl.experiments.tools.netns import Lab, unavailable

WHY = unavailable()

#: echoes one line per connection, on the host's loopback only
ECHO = """
import socket
s = socket.socket(); s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
s.bind(("127.0.0.1", 7001)); s.listen(); print("up", flush=True)
for _ in range(20):
    c, _ = s.accept(); c.sendall(c.recv(100)); c.close()
"""

#: prints the seconds of one exchange (connect, send, answer) with HOST:PORT (64 bytes: the
#: proxy holds fewer than a frame header's 12 until more come)
ROUND_TRIP = """
import socket, sys, time
t = time.monotonic()
with socket.create_connection((sys.argv[1], int(sys.argv[2])), timeout=10) as c:
    c.sendall(b"p" * 64); assert c.recv(100) == b"p" * 64
print(f"{time.monotonic() - t:.4f}")
"""


def _link(host, ms: float, port: int) -> subprocess.Popen:
    proc = host.popen(
        [
            sys.executable,
            "-m",
            "dfrl.experiments.tools.bench.delay_link",
            f"{host.address}:{port}",
            "127.0.0.1:7001",
            f"{ms:g}",
        ],
        stdout=subprocess.PIPE,
        text=True,
    )
    assert proc.stdout is not None
    assert proc.stdout.readline().startswith(f"delay_link listening on {host.address}:{port}")
    return proc


def _round_trip(host, address: str, port: int) -> float:
    out = host.run(
        [sys.executable, "-c", ROUND_TRIP, address, str(port)],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert out.returncode == 0, out.stderr
    return float(out.stdout)


@pytest.mark.skipif(WHY is not None, reason=WHY or "")
def test_a_delayed_link_costs_its_delay_each_way() -> None:
    with Lab(["a", "b"]) as lab:
        a, b = lab["a"], lab["b"]
        echo = b.popen([sys.executable, "-c", ECHO], stdout=subprocess.PIPE, text=True)
        assert echo.stdout is not None and echo.stdout.readline().strip() == "up"
        _link(b, 150, 7002)
        _link(b, 0, 7003)  # control: the same proxy, no delay
        slow = [_round_trip(a, b.address, 7002) for _ in range(3)]
        fast = [_round_trip(a, b.address, 7003) for _ in range(3)]
        # a request and its answer each wait 150 ms in the link (the connect does not)
        assert min(slow) >= 0.29, slow
        assert max(fast) < 0.15, fast
        # the server is on loopback only: a is reached through the link or not at all
        out = a.run(
            [sys.executable, "-c", ROUND_TRIP, b.address, "7001"],
            capture_output=True,
            text=True,
            timeout=30,
        )
        assert out.returncode != 0


def test_bad_link_arguments_exit_2() -> None:
    for argv in (["x", "127.0.0.1:1", "5"], ["127.0.0.1:0", "127.0.0.1:1", "-1"], []):
        out = subprocess.run(
            [sys.executable, "-m", "dfrl.experiments.tools.bench.delay_link", *argv],
            capture_output=True,
            text=True,
            timeout=30,
        )
        assert out.returncode == 2 and "usage:" in out.stderr, (argv, out.stderr)


def test_slow_links_stretch_the_time_bounds_by_a_round() -> None:
    base = Expectation()
    assert faults.slowed(base, 0.0, 4.2) == base
    assert faults.slowed(base, 50.0, None) == base
    slow = faults.slowed(base, 50.0, 4.2)
    assert (slow.recovery_bound_s, slow.stall_bound_s) == (
        base.recovery_bound_s + 4.2,
        base.stall_bound_s + 4.2,
    )
    with pytest.raises(ValueError, match="--delay-ms must be 0 to 2000"):
        faults.run(["kill_mid_hop"], delay_ms=-5)
