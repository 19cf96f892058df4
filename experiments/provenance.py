"""What produced a results folder: ``provenance.json``.

Every results folder of ``dfrl run`` / ``dfrl demo`` (written at the start of the run by
:mod:`dfrl.experiments.driver.launcher.experiment`) and of every study records the dfrl
version, the git commit when run from a checkout (and whether the checkout had changes), the
versions of Python, SWI-Prolog and of every package that shapes a result
(:data:`PACKAGES`: numpy, scipy, pybullet, gymnasium, pyswip, autograd, numba), the host, the
command line and the time::

    {"dfrl": "0.2.0",
     "git": {"commit": "4d1f3ae...", "dirty": true},
     "python": "3.11.7 (CPython)", "swipl": "9.2.9", "pybullet": "3.2.7", "numpy": "2.4.6",
     "scipy": "1.17.1", "gymnasium": "1.4.0", "pyswip": "0.3.3", "autograd": "1.9.1",
     "numba": "0.62.1",
     "host": {"name": "lab-3", "platform": "Linux-6.8.0-x86_64-with-glibc2.39", "cpus": 2},
     "command": ["dfrl", "paper", "--n-seeds", "5"], "cwd": "/work/main",
     "started": "2025-01-31T12:00:00Z"}

``git`` says why there is no commit when there is none: ``{"commit": null, "dirty": null,
"note": "not a checkout"}`` (an installed package), or ``"note": "git failed: ..."`` (a
checkout git could not read). A package that is not installed is ``null``, as is ``swipl``
without ``swipl`` on the PATH; finding a value never fails the run. The token never lands
here: the value after ``--token`` on the command line is replaced by ``<hidden>``.
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
#: The distributions whose versions are recorded (besides dfrl, Python and SWI-Prolog): what
#: the simulation, the learners and the bridge to Prolog run on.
PACKAGES: tuple[str, ...] = (
    "pybullet",
    "numpy",
    "scipy",
    "gymnasium",
    "pyswip",
    "autograd",
    "numba",
)
#: ``git``'s note when the package does not run from a git checkout.
NOT_A_CHECKOUT = "not a checkout"


def _output(argv: list[str], cwd: Path | None = None) -> str | None:
    try:
        done = subprocess.run(
            argv, cwd=cwd, capture_output=True, text=True, timeout=TIMEOUT_S, check=False
        )
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
def git_state() -> dict[str, Any]:
    """:func:`checkout_state` of the checkout this package runs from (if any)."""
    return checkout_state(_checkout())


def checkout_state(root: Path | None) -> dict[str, Any]:
    """``{"commit": sha, "dirty": bool}`` of the git checkout at ``root``; when there is no
    commit to give, ``commit`` and ``dirty`` are None and ``note`` says why (``root`` None:
    :data:`NOT_A_CHECKOUT`; else git failed there)."""
    if root is None:
        return {"commit": None, "dirty": None, "note": NOT_A_CHECKOUT}
    commit = _output(["git", "rev-parse", "HEAD"], root)
    if commit is None:
        return {
            "commit": None,
            "dirty": None,
            "note": f"git failed: no commit from git rev-parse HEAD in {root}",
        }
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

    return {
        "dfrl": dfrl.__version__,
        "git": dict(git_state()),
        "python": f"{platform.python_version()} ({platform.python_implementation()})",
        "swipl": swipl_version(),
        **{dist: _version(dist) for dist in PACKAGES},
        "host": {
            "name": socket.gethostname(),
            "platform": platform.platform(),
            "cpus": os.cpu_count(),
        },
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
    where = str(git.get("note") or NOT_A_CHECKOUT)
    if git.get("commit"):
        where = f"commit {str(git['commit'])[:10]}" + (", with changes" if git.get("dirty") else "")
    host = (p.get("host") or {}).get("name", "?")
    return (
        f"dfrl {p.get('dfrl')} ({where}), Python {p.get('python')}, SWI-Prolog "
        f"{p.get('swipl') or 'not found'}, pybullet {p.get('pybullet')}, numpy "
        f"{p.get('numpy')} on {host}"
    )
