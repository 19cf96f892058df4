"""``dfrl run --cluster ADDRESS --tls DIR``: the README's cluster (three namespaces made by the
test) with each worker's node TLS folder copied beside its ``dfrl.token`` as ``dfrl-tls``; the
placed services start with it, and the run completes over mutual TLS with identical tables.

A service without TLS could not answer the driver's mutual-TLS connections, so a complete run
shows the services used their folders. The control: a worker without the folder refuses to place its robot in a TLS run, with the
folder named, and nothing of the run starts (exit 1). Slow (about a minute).
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from dfrl.experiments.robot_host.cluster_task import TLS_FOLDER

from .readme_cluster import WORKERS, argv_of, cluster, driver_cmd, phase, rounds_of

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(shutil.which("openssl") is None, reason="needs openssl"),
]


def _certs(lab, drv: Path, tmp: Path, workers: list[str]) -> Path:  # noqa: ANN001
    """The README's node certificates from the project CA the cluster's recipe made (``ca``):
    one folder per worker host (copied beside its token as ``dfrl-tls``) and the driver's;
    returns the driver's folder."""

    def dfrl(*args: str) -> None:
        done = subprocess.run(
            [sys.executable, "-m", "dfrl", "certs", *args],
            cwd=drv,
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert done.returncode == 0, done.stderr

    assert (drv / "ca" / "ca.key").is_file()  # made by the README's cluster:certs block
    for w in workers:
        dfrl("node", lab[w].address, "ca", "--out", f"tls-{w}")
        shutil.copytree(drv / f"tls-{w}", tmp / w / TLS_FOLDER)
    dfrl("node", "driver", "ca", "--out", "tls-driver")
    return drv / "tls-driver"


def _run(lab, drv: Path, blocks: dict, tls: Path) -> subprocess.CompletedProcess:  # noqa: ANN001
    name, cfg = blocks["config"]
    planned = {**json.loads(cfg), "robots": json.loads(cfg)["robots"][:4]}
    (drv / name).write_text(json.dumps(planned), encoding="utf-8")
    argv = argv_of(driver_cmd(blocks, lab)) + ["--tls", str(tls)]
    return lab["head"].run(argv, cwd=drv, timeout=600, capture_output=True, text=True)


def test_a_tls_run_on_the_cluster_federates_over_tls(tmp_path: Path) -> None:
    with cluster(tmp_path, 2) as (lab, drv, blocks):
        tls = _certs(lab, drv, tmp_path, WORKERS)
        done = _run(lab, drv, blocks, tls)
        phase("driver exited")
        detail = f"exit {done.returncode}\n{done.stderr[-3000:]}"
        assert done.returncode == 0, detail
        out = drv / driver_cmd(blocks, lab).split("--out", 1)[1].split()[0]
        rows = rounds_of(out)
        assert rows and all(r["all_equal"] == "true" and r["skipped"] == "" for r in rows), rows
        nodes = json.loads((out / "nodes.json").read_text(encoding="utf-8"))
        assert nodes["tls"] == str(tls.resolve()), nodes
        record = json.loads((out / "cluster.json").read_text(encoding="utf-8"))
        assert record["losses"] == [] and len(record["placements"]) == 4, record


def test_a_worker_without_its_tls_folder_is_named(tmp_path: Path) -> None:
    with cluster(tmp_path, 2) as (lab, drv, blocks):
        tls = _certs(lab, drv, tmp_path, WORKERS)
        shutil.rmtree(tmp_path / "w2" / TLS_FOLDER)
        done = _run(lab, drv, blocks, tls)
        assert done.returncode == 1, done.stderr[-3000:]
        assert f"{tmp_path / 'w2' / TLS_FOLDER} is not a node TLS folder" in done.stderr, (
            done.stderr[-3000:]
        )
        assert "Traceback" not in done.stderr
        assert not (drv / "results" / "swarm" / "rounds.csv").exists()
