"""What ``dfrl run --cluster`` refuses, and says, before a robot starts: no token, a bad
``--cluster-cpus``, a worker without ``dfrl.token`` (a real Dask cluster in this process: its
task fails and the driver names the worker and the missing file), and that a plain run does not
import the engine."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from dfrl.experiments.errors import ExperimentError

distributed = pytest.importorskip(
    "distributed",
    reason="Dask distributed is not installed (pip install -e '.[cluster]'; scripts/test.sh does)",
)


def test_without_a_token_or_with_bad_cpus_nothing_starts(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> None:
    from dfrl.experiments.cli import main

    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("DFRL_TOKEN", raising=False)
    code = main(["run", "smoke2", "--cluster", "tcp://127.0.0.1:1", "--out", "o1"])
    err = capsys.readouterr().err
    assert code == 1 and "--token-file dfrl.token" in err and "Traceback" not in err, err
    assert not (tmp_path / "o1" / "nodes.json").exists()
    with pytest.raises(SystemExit) as bad:
        main(["run", "smoke2", "--cluster", "tcp://127.0.0.1:1", "--cluster-cpus", "0"])
    err = capsys.readouterr().err
    assert bad.value.code == 2 and "--cluster-cpus: must be > 0" in err, err


def test_a_worker_without_the_token_file_is_named(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from distributed import LocalCluster

    from dfrl.experiments.driver.launcher.cluster import ClusterPlacement

    monkeypatch.chdir(tmp_path)  # the worker's folder: no dfrl.token in it
    with LocalCluster(
        n_workers=1,
        threads_per_worker=2,
        processes=False,
        dashboard_address=":0",
        resources={"CPU": 2},
    ) as cluster:
        placement = ClusterPlacement(cluster.scheduler_address).open()
        try:
            with pytest.raises(ExperimentError) as err:
                placement.place(["r1"])
            # control: the same cluster holds 2 robots of 1 CPU, not 3
            with pytest.raises(ExperimentError, match="fit only 2 more at once"):
                placement.place(["r1", "r2", "r3"])
        finally:
            placement.release()
    text = str(err.value)
    assert "robot r1 was not placed" in text and "no token file" in text, text
    assert str(tmp_path / "dfrl.token") in text and "cluster worker" in text, text
    assert not list((tmp_path / "dfrl-robot" / "r1").glob("service-*.out"))


def test_a_plain_run_does_not_import_the_engine() -> None:
    code = (
        "import sys; from dfrl.experiments.cli import build_parser; "
        "from dfrl.experiments.cli.cluster import run_experiment_for; "
        "build_parser(); print('distributed' in sys.modules)"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stdout.strip() == "False", done.stderr
