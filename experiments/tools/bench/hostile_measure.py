"""What ``dfrl bench hostile`` measures of the target process and of the agent's hops."""

from __future__ import annotations

import os
import statistics
import threading
from pathlib import Path
from typing import Any

from dfrl.experiments.tools.bench.migrate import percentile


def proc_status(pid: int) -> dict[str, float]:
    """RSS (MB) and threads of a process, and its user + system CPU seconds."""
    out: dict[str, float] = {}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            out["rss_mb"] = int(line.split()[1]) / 1024
        elif line.startswith("Threads:"):
            out["threads"] = int(line.split()[1])
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    out["cpu_s"] = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return out


class Sampler(threading.Thread):
    """Peak RSS and threads of a process, sampled every 0.2 s until stopped."""

    def __init__(self, pid: int) -> None:
        super().__init__(daemon=True)
        self.pid, self.peak_rss, self.peak_threads = pid, 0.0, 0
        self.stopping = threading.Event()

    def run(self) -> None:
        while not self.stopping.wait(0.2):
            s = proc_status(self.pid)
            self.peak_rss = max(self.peak_rss, s["rss_mb"])
            self.peak_threads = max(self.peak_threads, int(s["threads"]))

    def stop(self) -> None:
        self.stopping.set()
        self.join(5)


def hop_figures(
    events: list[tuple], t0: float, t1: float, until: float, target_port: int
) -> dict[str, Any]:
    """Hops that departed in ``[t0, t1)``, their outcome known by ``until`` (event lines)."""
    departs = {(float(e[1]), e[2]) for e in events if e[0] == "DEPART" and t0 <= float(e[1]) < t1}
    arrived = {
        (float(e[1]), e[3]): (float(e[2]) - float(e[1])) * 1000.0
        for e in events
        if e[0] == "HOP" and float(e[2]) <= until
    }
    failed = [e for e in events if e[0] == "FAIL" and (float(e[1]), e[3]) in departs]
    ms = [arrived[d] for d in departs if d in arrived]
    into = [arrived[d] for d in departs if d in arrived and int(d[1]) != target_port]
    fig: dict[str, Any] = {
        "attempted": len(departs),
        "succeeded": len(ms),
        "failed": len(failed),
        "unfinished": len(departs) - len(ms) - len(failed),
        "fail_examples": [" ".join(e[5:])[:300] for e in failed[:3]],
    }
    for key, xs in (("hop", ms), ("into_target", into)):
        fig[f"{key}_median_ms"] = round(statistics.median(xs), 3) if xs else None
        fig[f"{key}_p90_ms"] = round(percentile(xs, 0.9), 3) if xs else None
        fig[f"{key}_max_ms"] = round(max(xs), 3) if xs else None
    return fig
