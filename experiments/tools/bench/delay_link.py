"""A slow link into a host: ``python -m dfrl.experiments.tools.bench.delay_link LISTEN TARGET MS``.

Runs one :class:`~.fault_proxy.FaultProxy` that listens on ``LISTEN`` (``host:port``) and
forwards every connection to ``TARGET``, holding every chunk ``MS`` milliseconds in each
direction, so a request and its reply cost ``2 * MS`` more. ``dfrl bench faults --delay-ms``
starts one inside every robot host's namespace, in front of its ``dfrl robot`` (which then
binds loopback and advertises the host's address): the kernel here has no ``netem`` queueing
discipline, so the delay is made in user space. Prints ``delay_link listening on HOST:PORT``
once it accepts connections; runs until SIGTERM or SIGINT.
"""

from __future__ import annotations

import signal
import sys
import threading

from dfrl.experiments.tools.bench.fault_proxy import FaultProxy

USAGE = (
    "usage: python -m dfrl.experiments.tools.bench.delay_link LISTEN_HOST:PORT TARGET_HOST:PORT MS"
)


def _address(text: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    if not sep or not host or not port.isdigit():
        raise ValueError(f"{text!r} is not HOST:PORT")
    return host, int(port)


def main(argv: list[str]) -> int:
    try:
        listen, target = _address(argv[0]), _address(argv[1])
        ms = float(argv[2])
        if ms < 0 or len(argv) != 3:
            raise ValueError("MS must be >= 0")
    except (IndexError, ValueError) as exc:
        print(f"delay_link: {exc}\n{USAGE}", file=sys.stderr)
        return 2
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    with FaultProxy(target, listen=listen, delay_s=ms / 1000.0) as proxy:
        print(f"delay_link listening on {proxy.address[0]}:{proxy.address[1]}", flush=True)
        while not stop.wait(1.0):
            pass
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
