"""What the fault tests of the dFRL agent share (test_dfrl_faults.py, test_resting_holder.py,
test_skip_stop.py): stop processes on fixed loopback ports, a console process that launches
agent ``fx`` from a plan file, and the round log (JSON lines) they read."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path

from .conftest import SWIPL, Proc, free_port
from .wire_client import request


class Tour:
    """Stops r0..r(n-1) on ports chosen now; subclasses start their processes. ``token``: the
    token of every node."""

    def __init__(self, tmp_path: Path, procs: list[Proc], n: int, token: int) -> None:
        self.tmp, self.procs, self.token = tmp_path, procs, token
        self.log = tmp_path / "rounds.jsonl"
        self.ports = [free_port() for _ in range(n)]
        self.launched = False

    def listening(self, i: int, make: Callable[[int], Proc], tries: int = 3) -> Proc:
        """Start stop ``i`` with ``make(port)`` and wait for its ``LISTENING`` line. Before the
        plan is launched, a port another process took since it was chosen (free_port() only
        finds one free at that moment) is replaced by a new one, at most ``tries`` times."""
        for attempt in range(tries):
            p = make(self.ports[i])
            self.procs.append(p)
            try:
                p.wait_for("LISTENING")
                return p
            except AssertionError:
                if (
                    self.launched
                    or attempt == tries - 1
                    or "Address already in use" not in p.output()
                ):
                    raise
                self.ports[i] = free_port()
        raise AssertionError("unreachable")

    def launch_plan(self, plan_term: str) -> None:
        """Write ``plan_term`` (a ``plan(...)`` term) to a file and run the console on it."""
        self.launched = True
        plan = self.tmp / "plan.txt"
        plan.write_text(plan_term + ".\n")
        c = Proc([SWIPL, "-q", "-g", "main", "-t", "halt", str(self.tmp / "console.pl"), str(plan)])
        self.procs.append(c)
        c.wait_for("LAUNCHED")

    def stops_term(self, ports: list[int] | None = None) -> str:
        """The plan's stops, ``stop(localhost, Port, r<i>)`` each."""
        return ",".join(f"stop(localhost,{p},r{i})" for i, p in enumerate(ports or self.ports))

    def events(self, kind: str | None = None) -> list[dict]:
        """The round log's events (of ``kind`` if given), in order."""
        if not self.log.exists():
            return []
        out = []
        for line in self.log.read_text().splitlines():
            if line.strip():
                e = json.loads(line)
                if kind is None or e["event"] == kind:
                    out.append(e)
        return out

    def has_agent(self, i: int, status: str = "") -> bool:
        """Node i lists agent fx (with ``status``, e.g. ``running``, if given)."""
        try:
            return f"agent(fx,dfrl_tour,mobile,{status}" in request(
                self.ports[i], "agents", token=str(self.token)
            )
        except (OSError, AssertionError):
            return False

    def wait(self, cond: Callable[[], object], timeout: float, what: str) -> None:
        """Until ``cond()`` is true, at most ``timeout`` seconds (then fail with the log)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if cond():
                return
            time.sleep(0.02)
        raise AssertionError(
            f"timed out waiting for {what}; log:\n"
            + "\n".join(json.dumps(e) for e in self.events())
        )

    def address(self, i: int) -> str:
        return f"localhost:{self.ports[i]}"
