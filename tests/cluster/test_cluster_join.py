"""A robot that joins a ``dfrl run --cluster`` run is placed on the cluster too: the README's
cluster (three namespaces made by the test), a run of 4 robots on workers offering 3 CPUs each,
``dfrl join`` of a fifth robot from the driver's host. It must run on a worker's host (the
control: never the driver's), be visited by later rounds with tables identical to the others',
and appear in ``cluster.json``; a sixth robot still fits, a seventh does not, and its join is
refused at once with the reason while the run goes on. Slow (about a minute).
"""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from dfrl.experiments.driver.results.agent_log import read_rounds_log

from .readme_cluster import WORKERS, argv_of, cluster, driver_cmd, phase, rounds_of

pytestmark = pytest.mark.slow

AGENT = "fed_qlearning"


def test_a_robot_that_joins_a_cluster_run_is_placed_on_the_cluster(tmp_path: Path) -> None:
    with cluster(tmp_path, 3) as (lab, drv, blocks):
        name, cfg = blocks["config"]
        planned = {**json.loads(cfg), "iterations": 6000, "rtf": 4.0, "timeout_s": 300}
        planned["robots"] = planned["robots"][:4]
        (drv / name).write_text(json.dumps(planned), encoding="utf-8")
        cmd = driver_cmd(blocks, lab)
        out = drv / cmd.split("--out", 1)[1].split()[0]
        driver = lab["head"].popen(
            argv_of(cmd), cwd=drv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        log = out / f"rounds_{AGENT}.log"
        deadline = time.monotonic() + 180
        while time.monotonic() < deadline and len(read_rounds_log(log, AGENT).rounds) < 1:
            time.sleep(0.2)
        assert log.is_file(), "no round within 180 s"
        phase("round 1 logged; r7 joins")

        def join(robot: str) -> subprocess.CompletedProcess:
            argv = [
                sys.executable,
                "-m",
                "dfrl",
                "join",
                str(out),
                "--robot",
                robot,
                "--arena",
                "r2",
                "--iterations",
                "900",
            ]
            return lab["head"].run(argv, cwd=drv, timeout=200, capture_output=True, text=True)

        joined = join("r7")
        assert joined.returncode == 0, joined.stdout + joined.stderr
        workers = {lab[w].address for w in WORKERS}
        host = joined.stdout.split("runs at ", 1)[1].split(":", 1)[0]
        assert host in workers and host != lab["head"].address, joined.stdout
        assert join("r8").returncode == 0  # 6 CPUs: 4 robots, r7 and r8
        t0 = time.monotonic()
        full = join("r9")
        assert full.returncode != 0 and "fit only 0 more at once" in full.stderr + full.stdout, (
            full.stdout + full.stderr
        )
        assert time.monotonic() - t0 < 60
        _, stderr = driver.communicate(timeout=400)
        phase("driver exited")
        detail = f"exit {driver.returncode}\n{stderr[-3000:]}"
        assert driver.returncode == 0, detail
        rows = rounds_of(out)
        late = [r for r in rows if "r7" in r["visited"].split()]
        assert late, detail
        for r in late:
            assert r["all_equal"] == "true" and r["skipped"] == "", r
        nodes = json.loads((out / "nodes.json").read_text(encoding="utf-8"))["nodes"]
        hosts = {n["robot"]: n["host"] for n in nodes}
        assert hosts.get("r7") in workers and "r9" not in hosts, hosts
        record = json.loads((out / "cluster.json").read_text(encoding="utf-8"))
        assert {"r7", "r8"} <= set(record["placements"]), record
