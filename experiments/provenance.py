"""What produced a results folder: ``provenance.json``.

Every results folder of ``dfrl run`` / ``dfrl demo`` (written at the start of the run by
:mod:`dfrl.experiments.driver.launcher.experiment`) and of every study records the dfrl
version, the git commit when run from a checkout (and whether the checkout had changes), the
versions of Python, SWI-Prolog, pybullet and numpy, the host, the command line and the time::

    {"dfrl": "0.2.0",
     "git": {"commit": "4d1f3ae...", "dirty": true},
     "python": "3.11.7 (CPython)", "swipl": "9.2.9", "pybullet": "3.2.7", "numpy": "2.4.6",
     "host": {"name": "lab-3", "platform": "Linux-6.8.0-x86_64-with-glibc2.39", "cpus": 2},
     "command": ["dfrl", "paper", "--n-seeds", "5"], "cwd": "/work/main",
     "started": "2025-01-31T12:00:00Z"}

A value that cannot be found is ``null`` (no checkout, no ``swipl`` on the PATH); finding it
never fails the run. The token never lands here: the value after ``--token`` on the command
line is replaced by ``<hidden>``.
"""
from __future__ import annotations

import json
import os
import platform
import socket
import subprocess
import sys
import time
from functools import lru_cache
from importlib import metadata
from pathlib import Path
from typing import Any

from dfrl.experiments.processes import find_swipl

#: The file name in a results folder.
PROVENANCE_FILE = "provenance.json"
#: Options whose value is a secret and is hidden in the recorded command line.
SECRET_OPTIONS = ("--token",)
#: Longest wait for ``git`` or ``swipl --version``.
TIMEOUT_S = 5.0


def _output(argv: list[str], cwd: Path | None = None) -> str | None:
    try:
        done = subprocess.run(argv, cwd=cwd, capture_output=True, text=True, timeout=TIMEOUT_S,
                              check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def _checkout() -> Path | None:
    """The root of the git checkout this package runs from, if any."""
    import dfrl

    here = Path(dfrl.__file__).resolve().parent
    for folder in (here, *here.parents):
        if (folder / ".git").exists():
            return folder
    return None


@lru_cache(maxsize=1)
def git_state() -> dict[str, Any] | None:
    """``{"commit": sha, "dirty": bool}`` of the checkout this package runs from; None when
    it is installed (not a checkout) or git is missing."""
    root = _checkout()
    if root is None:
        return None
    commit = _output(["git", "rev-parse", "HEAD"], root)
    if commit is None:
        return None
    status = _output(["git", "status", "--porcelain", "--untracked-files=no"], root)
    return {"commit": commit, "dirty": None if status is None else bool(status)}


@lru_cache(maxsize=1)
def swipl_version() -> str | None:
    """SWI-Prolog's version (``9.2.9``) from ``swipl --version``; None without swipl."""
    path = find_swipl()
    text = _output([path, "--version"]) if path else None
    if not text:
        return None
    words = text.split()
    return words[words.index("version") + 1] if "version" in words[:-1] else text


def _version(dist: str) -> str | None:
    try:
        return metadata.version(dist)
    except metadata.PackageNotFoundError:
        return None


def command_line(argv: list[str] | None = None) -> list[str]:
    """``argv`` (default: this process's, its program as ``dfrl`` when run as ``python -m
    dfrl``) with the values of :data:`SECRET_OPTIONS` hidden."""
    args = list(sys.argv if argv is None else argv)
    if args and Path(args[0]).name in ("__main__.py", "dfrl"):
        args[0] = "dfrl"
    out: list[str] = []
    hide = False
    for a in args:
        if hide:
            out.append("<hidden>")
            hide = False
        elif a in SECRET_OPTIONS:
            out.append(a)
            hide = True
        elif any(a.startswith(o + "=") for o in SECRET_OPTIONS):
            out.append(a.split("=", 1)[0] + "=<hidden>")
        else:
            out.append(a)
    return out


def provenance(argv: list[str] | None = None) -> dict[str, Any]:
    """What is producing results now: versions, commit, host, command line (see the module's
    docs for the fields)."""
    import dfrl
    import numpy

    return {
        "dfrl": dfrl.__version__,
        "git": git_state(),
        "python": f"{platform.python_version()} ({platform.python_implementation()})",
        "swipl": swipl_version(),
        "pybullet": _version("pybullet"),
        "numpy": numpy.__version__,
        "host": {"name": socket.gethostname(), "platform": platform.platform(),
                 "cpus": os.cpu_count()},
        "command": command_line(argv),
        "cwd": os.getcwd(),
        "started": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }


def write_provenance(folder: str | Path, argv: list[str] | None = None) -> Path:
    """Write ``provenance.json`` into ``folder`` (created if missing); return its path."""
    path = Path(folder) / PROVENANCE_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(provenance(argv), indent=1) + "\n", encoding="utf-8")
    return path


def read_provenance(folder: str | Path) -> dict[str, Any] | None:
    """``provenance.json`` of ``folder``; None when it is missing or unreadable."""
    try:
        data = json.loads((Path(folder) / PROVENANCE_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def describe(p: dict[str, Any]) -> str:
    """One line for a summary: ``dfrl 0.2.0 (commit 4d1f3ae, with changes), Python 3.11.7,
    SWI-Prolog 9.2.9, pybullet 3.2.7, numpy 2.4.6 on lab-3``."""
    git = p.get("git") or {}
    where = "not a checkout"
    if git.get("commit"):
        where = f"commit {str(git['commit'])[:10]}" + (", with changes" if git.get("dirty")
                                                       else "")
    host = (p.get("host") or {}).get("name", "?")
    return (f"dfrl {p.get('dfrl')} ({where}), Python {p.get('python')}, SWI-Prolog "
            f"{p.get('swipl') or 'not found'}, pybullet {p.get('pybullet')}, numpy "
            f"{p.get('numpy')} on {host}")
