"""The gates of scripts/gates.sh: each one fails on a copy broken on purpose, naming the file, and
passes on the real tree (ruff, mypy, the import contracts)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SCRIPTS = ROOT / "scripts"
#: typeshed's stubs analysed once for every tiny package of these tests (mypy's own cache)
MYPY_CACHE = ROOT / "build" / "mypy_cache_tests"
#: the modules the import contracts of pyproject.toml name (layers and shared modules)
CONTRACT_MODULES = (
    "experiments/cli",
    "experiments/tools",
    "experiments/science",
    "experiments/driver",
    "experiments/robot_host",
    "pybridge",
    "robots",
    "arenas",
    "platform_pl",
    *(
        f"experiments/{m}.py"
        for m in (
            "errors",
            "processes",
            "tokens",
            "tls_folder",
            "config_rules",
            "provenance",
            "suggestions",
        )
    ),
)


def _run(*cmd: str | Path, cwd: Path = ROOT, **env: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [str(c) for c in cmd],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, **env},
        check=False,
    )


def _project(tmp_path: Path, files: dict[str, str]) -> Path:
    """A tiny checkout: the real pyproject.toml and setup.py (its ROOTS), ``dfrl/``, a package
    for every folder the contracts name, and ``files`` on top."""
    for name in ("pyproject.toml", "setup.py"):
        shutil.copy(ROOT / name, tmp_path / name)
    (tmp_path / "dfrl").mkdir()
    (tmp_path / "dfrl" / "__init__.py").write_text('"""a tiny dfrl."""\n')
    for module in ("experiments", *CONTRACT_MODULES):
        path = tmp_path / module
        if path.suffix == ".py":
            path.write_text("")
        else:
            path.mkdir(parents=True, exist_ok=True)
            (path / "__init__.py").write_text("")
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    return tmp_path


def test_ruff_fails_on_an_unused_import_naming_the_file(tmp_path: Path) -> None:
    root = _project(
        tmp_path, {"robots/unused.py": '"""Imports what it never uses."""\nimport os\n'}
    )
    done = _run(sys.executable, "-m", "ruff", "check", "--no-cache", "robots", cwd=root)
    assert done.returncode != 0
    assert "robots/unused.py" in done.stdout and "F401" in done.stdout


def test_ruff_format_check_fails_on_a_file_laid_out_by_hand_naming_it(tmp_path: Path) -> None:
    text = '"""Laid out by hand."""\n\nVALUES = {  "a":1,\n           "b":2}\n'
    root = _project(tmp_path, {"robots/by_hand.py": text})
    done = _run(sys.executable, "-m", "ruff", "format", "--check", "--no-cache", "robots", cwd=root)
    assert done.returncode == 1 and "robots/by_hand.py" in done.stdout, done.stdout
    # control: the same file once formatted passes
    assert (
        _run(sys.executable, "-m", "ruff", "format", "--no-cache", "robots", cwd=root).returncode
        == 0
    )
    done = _run(sys.executable, "-m", "ruff", "format", "--check", "--no-cache", "robots", cwd=root)
    assert done.returncode == 0, done.stdout


def test_mypy_follows_dfrl_to_the_folders_and_fails_naming_the_file(tmp_path: Path) -> None:
    # the error is only seen if dfrl.robots.counts resolves to robots/counts.py
    root = _project(
        tmp_path,
        {
            "robots/counts.py": "COUNT: int = 3\n",
            "robots/words.py": "from dfrl.robots.counts import COUNT\n\nWORD: str = COUNT\n",
        },
    )
    done = _run(
        sys.executable, SCRIPTS / "typecheck.py", "--root", root, MYPY_CACHE_DIR=str(MYPY_CACHE)
    )
    assert done.returncode != 0, done.stdout
    assert "robots/words.py:3: error" in done.stdout and "build/typecheck" not in done.stdout
    assert "[assignment]" in done.stdout
    (root / "robots" / "words.py").write_text(
        "from dfrl.robots.counts import COUNT\n\nWORD: str = str(COUNT)\n"
    )
    done = _run(
        sys.executable, SCRIPTS / "typecheck.py", "--root", root, MYPY_CACHE_DIR=str(MYPY_CACHE)
    )
    assert done.returncode == 0, done.stdout


def test_import_contracts_fail_on_a_robot_host_importing_a_tool(tmp_path: Path) -> None:
    root = _project(
        tmp_path,
        {
            "experiments/tools/probe.py": "VALUE = 1\n",
            "experiments/robot_host/process.py": "def main() -> int:\n"
            "    from dfrl.experiments.tools.probe import VALUE\n"
            "    return VALUE\n",
        },
    )
    done = _run(sys.executable, SCRIPTS / "import_contracts.py", "--root", root)
    assert done.returncode != 0, done.stdout + done.stderr
    assert "rooms: cli -> tools -> science -> driver -> robot_host BROKEN" in done.stdout
    assert "dfrl.experiments.robot_host.process -> dfrl.experiments.tools.probe" in done.stdout
    (root / "experiments/robot_host/process.py").write_text("def main() -> int:\n    return 0\n")
    done = _run(sys.executable, SCRIPTS / "import_contracts.py", "--root", root)
    assert done.returncode == 0, done.stdout + done.stderr


def test_prolog_graph_fails_on_a_load_cycle_and_on_a_platform_module_naming_dfrl(
    tmp_path: Path,
) -> None:
    root = _project(
        tmp_path,
        {
            "platform_pl/ring_a.pl": ":- module(ring_a, []).\n:- use_module(ring_b, [b/0]).\n",
            "platform_pl/sub/ring_b.pl": "",  # replaced below: the cycle crosses folders
            "platform_pl/dfrl_agent/dfrl_fold.pl": ":- module(dfrl_fold, [fold/2]).\nfold(X, X).\n",
            "platform_pl/safe.pl": (
                ":- module(safe, [hook/1]).\n"
                "% dfrl_fold:fold/2 in a comment is no reference\n"
                "note('dfrl_fold:fold').\n"
                "hook(dfrl_fold:fold/2).\n"
            ),
            "platform_pl/clean.pl": ":- module(clean, []).\n:- use_module(library(lists)).\n",
        },
    )
    (root / "platform_pl/sub/ring_b.pl").unlink()
    (root / "platform_pl/ring_b.pl").write_text(
        ":- module(ring_b, [b/0]).\n:- use_module('sub/../ring_a').\nb.\n"
    )
    done = _run(sys.executable, SCRIPTS / "prolog_graph.py", "--root", root)
    assert done.returncode == 1
    lines = done.stdout.splitlines()
    assert "load cycle: platform_pl/ring_a.pl, platform_pl/ring_b.pl load each other" in lines
    assert lines[-1].startswith(
        "platform_pl/safe.pl: platform module safe names the dFRL "
        "application (qualifies with dfrl_fold)"
    )
    assert not any("clean.pl" in line or "dfrl_agent/" in line.split(":")[0] for line in lines)
    warned = _run(sys.executable, SCRIPTS / "prolog_graph.py", "--root", root, "--warn")
    assert warned.returncode == 0 and warned.stdout == done.stdout
    for name in ("ring_b.pl", "safe.pl"):
        (root / "platform_pl" / name).unlink()
    done = _run(sys.executable, SCRIPTS / "prolog_graph.py", "--root", root)
    assert done.returncode == 0 and done.stdout == ""
    (root / "platform_pl/clean.pl").write_text(":- module(clean, []).\n" + "c.\n" * 500)
    done = _run(sys.executable, SCRIPTS / "prolog_graph.py", "--root", root)
    assert done.returncode == 1
    assert done.stdout == "platform_pl/clean.pl: module clean has 501 lines, over 500\n"


@pytest.mark.parametrize("gate", ["ruff", "mypy", "import-contracts"])
def test_the_real_tree_passes(gate: str) -> None:
    cmd = {
        "ruff": [
            sys.executable,
            "-m",
            "ruff",
            "check",
            "--no-cache",
            "platform_pl",
            "pybridge",
            "robots",
            "arenas",
            "experiments",
            "dfrl",
            "scripts",
            "tests",
        ],
        "mypy": [sys.executable, SCRIPTS / "typecheck.py"],
        "import-contracts": [sys.executable, SCRIPTS / "import_contracts.py"],
    }[gate]
    done = _run(*cmd)
    assert done.returncode == 0, done.stdout + done.stderr


def test_prolog_graph_that_reads_nothing_fails(tmp_path: Path) -> None:
    done = _run(sys.executable, SCRIPTS / "prolog_graph.py", "--root", tmp_path)
    assert done.returncode == 2 and "no Prolog sources read" in done.stderr, done.stderr
    (tmp_path / "platform_pl").mkdir()
    done = _run(sys.executable, SCRIPTS / "prolog_graph.py", "--root", tmp_path, "--warn")
    assert done.returncode == 2 and "missing folders: pybridge" in done.stderr, done.stderr
