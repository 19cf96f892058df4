"""``dfrl paper --cluster``: a study's federated runs spread over the README's cluster (three
namespaces made by the test: scheduler and driver in ``head``, workers in ``w1`` and ``w2``).

Two seeds of the paper's four federations (5 robots each) on workers offering 5 CPUs each: the
cluster holds two runs at once, so runs must overlap in time (the control that they are spread,
not queued one after the other), every run's robots must sit on workers' hosts (none on the
driver's), every run must complete, and the report must be written. Slow (about 3 minutes).
"""

from __future__ import annotations

import json
import re
import sys
from pathlib import Path

import pytest

from .readme_cluster import WORKERS, cluster, phase

pytestmark = pytest.mark.slow


def _interval(out: Path) -> tuple[float, float]:
    """(start, end) of one run in seconds since the epoch: when its ``config.json`` (at its
    start) and its ``summary.md`` (at its end) were written."""
    return (out / "config.json").stat().st_mtime, (out / "summary.md").stat().st_mtime


def test_paper_spreads_its_federations_over_the_cluster(tmp_path: Path) -> None:
    with cluster(tmp_path, 5) as (lab, drv, blocks):
        token = drv / blocks["token"][1].split("--out", 1)[1].split()[0]
        driver = blocks["driver"][1].split()
        address = driver[driver.index("--cluster") + 1].replace("HEAD", lab["head"].address)
        member = drv / driver[driver.index("--cluster-tls") + 1]
        argv = [
            sys.executable,
            "-m",
            "dfrl",
            "paper",
            "--out",
            "paper",
            "--n-seeds",
            "2",
            "--iterations",
            "200",
            "--respite",
            "100",
            "--eval-points",
            "1",
            "--eval-steps",
            "50",
            "--no-control",
            "--jobs",
            "1",
            "--cluster",
            address,
            "--cluster-tls",
            str(member),
            "--token-file",
            str(token),
        ]
        done = lab["head"].run(argv, cwd=drv, timeout=900, capture_output=True, text=True)
        phase("paper exited")
        detail = f"exit {done.returncode}\n{done.stderr[-4000:]}"
        assert done.returncode == 0, detail
        assert re.search(r"8 federated runs on cluster \S+, 2 at once", done.stderr), detail
        runs = sorted(p.parent for p in (drv / "paper").glob("seed*/*/cluster.json"))
        assert len(runs) == 8, (runs, detail)
        workers = {lab[w].address for w in WORKERS}
        for out in runs:
            summary = (out / "summary.md").read_text(encoding="utf-8")
            assert "federation complete" in summary, (out, summary)
            nodes = json.loads((out / "nodes.json").read_text(encoding="utf-8"))["nodes"]
            hosts = {n["host"] for n in nodes}
            assert len(nodes) == 5 and hosts <= workers, (out, hosts)
            assert lab["head"].address not in hosts
        spans = sorted(_interval(out) for out in runs)
        overlaps = sum(1 for a, b in zip(spans, spans[1:]) if b[0] < a[1])
        assert overlaps >= 1, spans
        assert (drv / "paper" / "report.md").is_file(), detail
