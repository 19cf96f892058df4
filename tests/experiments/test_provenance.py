"""provenance.json: what produced a results folder, written without failing and without the
token; summary.md names it."""

from __future__ import annotations

import json
import platform
from importlib import metadata
import subprocess
from pathlib import Path

import numpy as np

import dfrl
from dfrl.experiments.provenance import (
    NOT_A_CHECKOUT,
    PACKAGES,
    PROVENANCE_FILE,
    checkout_state,
    command_line,
    describe,
    provenance,
    read_provenance,
    write_provenance,
)

ROOT = Path(__file__).resolve().parents[2]


def test_fields_and_versions(tmp_path: Path) -> None:
    # Execute
    path = write_provenance(tmp_path / "new", ["/usr/bin/dfrl", "paper", "--n-seeds", "3"])
    # Assert
    p = json.loads(path.read_text(encoding="utf-8"))
    assert path.name == PROVENANCE_FILE and read_provenance(tmp_path / "new") == p
    assert set(p) == {
        "dfrl",
        "git",
        "python",
        "swipl",
        "pybullet",
        "numpy",
        "scipy",
        "gymnasium",
        "pyswip",
        "autograd",
        "numba",
        "host",
        "command",
        "cwd",
        "started",
    }
    assert p["dfrl"] == dfrl.__version__ and p["numpy"] == np.__version__
    # every package the runs stand on, with the version installed (None: not installed)
    for dist in PACKAGES:
        try:
            assert p[dist] == metadata.version(dist), dist
        except metadata.PackageNotFoundError:
            assert p[dist] is None, dist
    assert p["scipy"] and p["gymnasium"] and p["pyswip"] and p["autograd"]
    assert p["python"].startswith(platform.python_version())
    assert p["command"] == ["dfrl", "paper", "--n-seeds", "3"]
    assert p["host"]["name"] and p["host"]["cpus"] >= 1
    assert p["started"].endswith("Z")


def test_commit_of_the_checkout() -> None:
    head = subprocess.run(
        ["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True, check=False
    )
    p = provenance([])
    if head.returncode != 0:  # not a checkout (an installed package)
        assert p["git"] == {"commit": None, "dirty": None, "note": NOT_A_CHECKOUT}
        return
    assert p["git"]["commit"] == head.stdout.strip()
    assert p["git"]["dirty"] in (True, False, None)


def test_no_commit_says_why(tmp_path: Path) -> None:
    # an installed package (no checkout), and a folder git cannot read (no repository)
    assert checkout_state(None) == {"commit": None, "dirty": None, "note": "not a checkout"}
    failed = checkout_state(tmp_path)
    assert failed["commit"] is None and failed["note"].startswith("git failed")
    assert str(tmp_path) in failed["note"]
    assert "(not a checkout)" in describe({"git": checkout_state(None)})


def test_token_never_recorded() -> None:
    assert command_line(["dfrl", "node", "--token", "s3cret", "--port", "0"]) == [
        "dfrl",
        "node",
        "--token",
        "<hidden>",
        "--port",
        "0",
    ]
    assert command_line(["x/__main__.py", "robot", "--token=s3cret"]) == [
        "dfrl",
        "robot",
        "--token=<hidden>",
    ]


def test_missing_or_broken_file_reads_as_none(tmp_path: Path) -> None:
    assert read_provenance(tmp_path) is None
    (tmp_path / PROVENANCE_FILE).write_text("{not json", encoding="utf-8")
    assert read_provenance(tmp_path) is None


def test_describe_names_commit_and_versions() -> None:
    p = {
        "dfrl": "0.2.0",
        "git": {"commit": "4d1f3ae0123456789", "dirty": True},
        "python": "3.11.7 (CPython)",
        "swipl": "9.0.4",
        "pybullet": "3.2.7",
        "numpy": "2.4.6",
        "host": {"name": "lab"},
    }
    assert describe(p) == (
        "dfrl 0.2.0 (commit 4d1f3ae012, with changes), Python 3.11.7 "
        "(CPython), SWI-Prolog 9.0.4, pybullet 3.2.7, numpy 2.4.6 on lab"
    )
    assert "(not a checkout)" in describe({**p, "git": None, "swipl": None})
    assert "SWI-Prolog not found" in describe({**p, "git": None, "swipl": None})
