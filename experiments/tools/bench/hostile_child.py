"""The benchmark's Python attackers in a process of their own, at the lowest CPU priority.

``python -m dfrl.experiments.tools.bench.hostile_child SPEC`` (``SPEC`` a JSON object with ``kind``:
``slowloris``, ``flood``, ``frames`` or ``authframes``, and that attacker's arguments) lowers its
own priority (``os.nice(19)``), starts the attacker, prints ``{"event": "started"}``, runs until
its standard input closes, stops the attacker and prints one JSON line: ``{"event": "result",
"result": {...}}`` or ``{"event": "error", "error": "..."}``. Threads of the benchmark's own
process would compete with the nodes for the CPU at the same priority (and for the
benchmark's GIL); a nice'd process leaves the CPU to the nodes, so that what is measured is the
node under attack, not the machine. :class:`ChildAttacker` is the parent's side.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from typing import Any

from dfrl.experiments import processes
from dfrl.experiments.tools.bench.hostile_attacks import FrameSenders, Swarm, sources
from dfrl.experiments.tools.bench.hostile_auth_attacks import AuthFrames


def build(spec: dict[str, Any]) -> Swarm | FrameSenders | AuthFrames:
    """The attacker that ``spec`` describes (see the module doc)."""
    kind, port, max_s = spec["kind"], spec["port"], spec["max_s"]
    if kind in ("slowloris", "flood"):
        return Swarm(
            port,
            spec["n"],
            sources(spec["sources"]),
            trickle=kind == "slowloris",
            reconnect_s=spec["reconnect_s"],
            max_s=max_s,
        )
    if kind == "frames":
        return FrameSenders(
            port,
            spec["n"],
            spec["frame_size"],
            sources(spec["sources"]),
            spec["pause_s"],
            max_s=max_s,
            kinds=tuple(spec["kinds"]),
        )
    if kind == "authframes":
        return AuthFrames(
            port, spec["token"], spec["big"], spec["big_size"], spec["flood"], max_s=max_s
        )
    raise ValueError(f"unknown attacker kind {kind!r}")


def main(argv: list[str]) -> int:
    os.nice(19)
    try:
        attacker = build(json.loads(argv[0]))
        attacker.start()
    except Exception as exc:  # noqa: BLE001 - reported to the parent
        print(json.dumps({"event": "error", "error": repr(exc)}), flush=True)
        return 1
    print(json.dumps({"event": "started"}), flush=True)
    sys.stdin.read()
    try:
        out = {"event": "result", "result": attacker.stop()}
    except Exception as exc:  # noqa: BLE001 - reported to the parent
        out = {"event": "error", "error": repr(exc)}
    print(json.dumps(out), flush=True)
    return 0


class ChildAttacker:
    """The parent's side: start the child, and stop it for its result."""

    def __init__(self, spec: dict[str, Any]) -> None:
        self.spec = spec
        self.proc: subprocess.Popen[str] | None = None
        self.lines: list[str] = []

    def start(self) -> None:
        self.proc = processes.start(
            [
                sys.executable,
                "-m",
                "dfrl.experiments.tools.bench.hostile_child",
                json.dumps(self.spec),
            ],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
        )
        assert self.proc.stdout is not None
        first = self.proc.stdout.readline()
        if '"started"' not in first:
            self.stop()
            raise RuntimeError(f"attacker {self.spec['kind']} did not start: {first[:500]}")

    def stop(self, timeout_s: float = 90.0) -> dict[str, Any]:
        assert self.proc is not None
        box: dict[str, Any] = {}

        def communicate() -> None:
            box["out"], box["err"] = self.proc.communicate()  # type: ignore[union-attr]

        t = threading.Thread(target=communicate, daemon=True)
        t.start()
        t.join(timeout_s)
        if t.is_alive():
            processes.stop(self.proc)
            t.join(10)
            raise RuntimeError(f"attacker {self.spec['kind']} did not stop in {timeout_s:g} s")
        lines = [json.loads(x) for x in box["out"].splitlines() if x.startswith("{")]
        result = next((x for x in lines if x["event"] in ("result", "error")), None)
        if result is None or result["event"] == "error":
            raise RuntimeError(
                f"attacker {self.spec['kind']} failed: "
                f"{(result or {}).get('error', box['err'][-2000:])}"
            )
        return result["result"]


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
