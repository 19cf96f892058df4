"""Robots placed on a Dask cluster, following experiments/README.md "Running on a cluster"
word for word: a cluster of three network namespaces made by the test (the scheduler and the
driver in ``head``, a worker in ``w1`` and ``w2``), the section's certificates, its ``dask
scheduler``, ``dask worker`` and ``dfrl run --cluster`` commands (mutual TLS), its config
(the set-up: readme_cluster.py; what a stranger gets: test_cluster_stranger.py). The run must complete with every
round visiting every robot and leaving identical tables, every robot on a worker's host (none
on the driver's), its files back over the platform. A worker killed mid-run (every process of
its namespace, kill -9) must be reported like a lost robot host: its robots skipped and LOST,
the worker named under "Cluster", exit status 1, no traceback.

The control: each robot's address in ``nodes.json`` is a worker's, never the driver's host
(test_cluster_errors.py has the refusals: no token, too few CPUs, no token file on a worker).

Runs in CI (as root, ``distributed`` installed by scripts/test.sh); skipped with the reason
where namespaces cannot be made or the engine is missing.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from dfrl.experiments.driver.results.agent_log import read_rounds_log
from dfrl.experiments.tools.netns import Lab

from .readme_cluster import (
    WHY,
    WORKERS,
    argv_of,
    cluster,
    cluster_blocks,
    driver_cmd,
    logs_of,
    phase,
    rounds_of,
)

pytestmark = pytest.mark.skipif(WHY is not None, reason=WHY or "")


def federate(tmp_path: Path, lab: Lab, drv: Path, blocks: dict, cfg: str) -> str:
    """Run the README's driver command on ``cfg`` and check what the section promises: exit
    0, every planned round visiting every robot with identical tables, every robot on a
    worker's host (control: none on the driver's), both workers used, every task released,
    every robot's files back over the platform. Returns the driver command."""
    name = blocks["config"][0]
    (drv / name).write_text(cfg, encoding="utf-8")
    cmd = driver_cmd(blocks, lab)
    done = lab["head"].run(argv_of(cmd), cwd=drv, timeout=600, capture_output=True, text=True)
    phase("driver exited")
    (drv / "driver.err").write_text(done.stderr, encoding="utf-8")
    detail = f"exit {done.returncode}\n{done.stderr[-3000:]}"
    assert done.returncode == 0, detail
    out = drv / cmd.split("--out", 1)[1].split()[0]
    planned = json.loads(cfg)
    robots = [r["id"] for r in planned["robots"]]
    rows = rounds_of(out)
    assert len(rows) == -(-planned["iterations"] // planned["respite"]), detail
    for row in rows:
        assert row["visited"].split() == robots, row
        assert row["skipped"] == "" and row["all_equal"] == "true", row
        assert len({row[f"digest_{r}"] for r in robots}) == 1, row
    workers = {lab[w].address for w in WORKERS}
    nodes = json.loads((out / "nodes.json").read_text(encoding="utf-8"))["nodes"]
    hosts = {n["robot"]: n["host"] for n in nodes}
    assert set(hosts) == set(robots) and set(hosts.values()) == workers, hosts
    record = json.loads((out / "cluster.json").read_text(encoding="utf-8"))
    assert record["losses"] == [], record
    assert all(
        t["ended"] == "released by the driver" and t["exit"] == 0 for t in record["tasks"].values()
    ), (record["tasks"], logs_of(tmp_path))
    for r in robots:  # files came back over the platform from the workers' folders
        assert (out / f"metrics_{r}.csv").stat().st_size > 0
        assert (out / "tables" / f"{r}.npy").is_file()
        w = next(w for w in WORKERS if lab[w].address == hosts[r])
        assert list((tmp_path / w / "dfrl-robot" / r).glob(f"*/metrics_{r}.csv"))
    summary = (out / "summary.md").read_text(encoding="utf-8")
    assert "federation complete" in summary and "## Cluster" in summary, summary
    return cmd


def test_the_documented_cluster_run_federates_robots_placed_on_workers(tmp_path: Path) -> None:
    t0 = time.monotonic()
    with cluster(tmp_path, 3) as (lab, drv, blocks):
        federate(tmp_path, lab, drv, blocks, blocks["config"][1])
    assert time.monotonic() - t0 < 300


@pytest.mark.slow
def test_24_robots_placed_on_the_cluster_federate(tmp_path: Path) -> None:
    """The issue's size: the README's config grown to 24 robots (arenas in turn), 12 per
    worker."""
    blocks = cluster_blocks()
    planned = json.loads(blocks["config"][1])
    arenas = [r["arena"] for r in planned["robots"]]
    planned["robots"] = [{"id": f"r{i + 1}", "arena": arenas[i % len(arenas)]} for i in range(24)]
    planned["iterations"], planned["respite"], planned["timeout_s"] = 200, 100, 600
    with cluster(tmp_path, 12) as (lab, drv, blocks):
        federate(tmp_path, lab, drv, blocks, json.dumps(planned))


def test_a_killed_cluster_worker_is_reported_like_a_lost_host(tmp_path: Path) -> None:
    with cluster(tmp_path, 2) as (lab, drv, blocks):
        name, cfg = blocks["config"]
        planned = {**json.loads(cfg), "iterations": 600, "rtf": 4.0, "timeout_s": 150}
        planned["robots"] = planned["robots"][:4]  # 2 per worker: half of them lost
        (drv / name).write_text(json.dumps(planned), encoding="utf-8")
        cmd = driver_cmd(blocks, lab)
        out = drv / cmd.split("--out", 1)[1].split()[0]
        driver = lab["head"].popen(
            argv_of(cmd), cwd=drv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        log = out / "rounds_fed_qlearning.log"
        deadline = time.monotonic() + 180  # placing 6 services on a loaded CI
        while time.monotonic() < deadline and len(read_rounds_log(log, "fed_qlearning").rounds) < 1:
            time.sleep(0.1)
        assert log.is_file(), "no round within 180 s"
        nodes = json.loads((out / "nodes.json").read_text(encoding="utf-8"))["nodes"]
        gone = sorted(n["robot"] for n in nodes if n["host"] == lab["w2"].address)
        assert len(gone) == 2, nodes
        phase(f"round 1 logged; killing w2 ({', '.join(gone)})")
        for pid in _pids_in(lab["w2"].namespace):  # the node dies: every process on it
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        _, stderr = driver.communicate(timeout=300)
        phase("driver exited")
        (drv / "driver.err").write_text(stderr, encoding="utf-8")
        detail = f"exit {driver.returncode}\n{stderr[-3000:]}"
        assert driver.returncode == 1, detail
        assert "Traceback" not in stderr, detail
        assert "CLUSTER: cluster worker" in stderr and "left the cluster" in stderr, detail
        rows = rounds_of(out)
        assert [int(r["round"]) for r in rows] == list(range(1, 7)), detail
        late = [r for r in rows if not set(gone) & set(r["visited"].split())]
        assert late, detail
        for r in late:
            assert all(g in r["skipped"] for g in gone), r
            assert r["all_equal"] == "true", r
        summary = (out / "summary.md").read_text(encoding="utf-8")
        assert "federation INCOMPLETE" in summary, summary
        for g in gone:
            assert f"LOST robot {g}" in summary, summary
        cluster_part = summary.split("## Cluster", 1)[1]
        assert f"{lab['w2'].address}" in cluster_part and "left the cluster" in cluster_part
        kept = [n["robot"] for n in nodes if n["robot"] not in gone]
        for r in kept:
            assert (out / f"metrics_{r}.csv").stat().st_size > 0


def _pids_in(ns: str) -> list[int]:
    done = subprocess.run(["ip", "netns", "pids", ns], capture_output=True, text=True)
    return [int(p) for p in done.stdout.split()] if done.returncode == 0 else []
