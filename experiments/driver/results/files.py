"""JSON files of a results folder (``config.json``, ``nodes.json``, launch and node configs), and
claiming the folder of a new run (:func:`claim_output`, :func:`new_run_folder`; a folder a
caller claimed travels as a :class:`ClaimedFolder`, so that it is claimed once)."""
from __future__ import annotations

import json
import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any


def read_json(path: str | Path) -> Any:
    """A JSON file's content."""
    return json.loads(Path(path).read_text(encoding="utf-8"))


def write_json(path: str | Path, data: Any) -> Path:
    """Write JSON (indented, trailing newline) atomically enough for readers polling it."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_suffix(p.suffix + ".tmp")
    tmp.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    tmp.replace(p)
    return p


@dataclass(frozen=True)
class ClaimedFolder:
    """A results folder claimed for one run (by :func:`claim_output` or
    :func:`new_run_folder`): whoever gets it writes into it without claiming it again."""

    path: Path


#: Files whose presence marks a folder as a dfrl results folder (``--force`` empties only such).
RESULTS_MARKERS = ("config.json", "nodes.json", "summary.md", "metrics.csv")


def claim_output(out: str | Path, force: bool = False) -> Path:
    """Make ``out`` the empty folder of a new run: created if missing; a non-empty folder is
    refused, or with ``force`` emptied first (only a results folder: one holding
    :data:`RESULTS_MARKERS` or nothing else).

    Raises
    ------
    FileExistsError
        ``out`` is not empty (without ``force``), is a file, or is not a results folder.
    """
    p = Path(out)
    if p.exists() and not p.is_dir():
        raise FileExistsError(f"{p} is a file, not a results folder")
    if p.is_dir() and any(p.iterdir()):
        if not force:
            raise FileExistsError(f"{p} is not empty (results of an earlier run?); choose "
                                  "another --out, or --force to empty it first")
        if not any((p / m).exists() for m in RESULTS_MARKERS):
            raise FileExistsError(f"{p} does not look like a results folder (none of "
                                  f"{', '.join(RESULTS_MARKERS)}); not emptying it")
        for child in p.iterdir():
            if child.is_dir() and not child.is_symlink():
                shutil.rmtree(child)
            else:
                child.unlink()
    p.mkdir(parents=True, exist_ok=True)
    return p


def new_run_folder(root: str | Path, name: str, stamp: str | None = None) -> Path:
    """A new, empty folder ``root/name/<timestamp>`` (``-2``, ``-3`` ... when taken) with
    ``root/name/latest`` pointing at it (a relative symbolic link, replaced atomically)."""
    base = Path(root) / name
    base.mkdir(parents=True, exist_ok=True)
    stamp = stamp or time.strftime("%Y-%m-%dT%H-%M-%S")
    for n in range(1, 1000):
        cand = base / (stamp if n == 1 else f"{stamp}-{n}")
        try:
            cand.mkdir()
            break
        except FileExistsError:
            continue
    else:
        raise FileExistsError(f"no free run folder under {base}")
    link = base / "latest"
    tmp = base / f".latest.{os.getpid()}"
    if tmp.is_symlink() or tmp.exists():
        tmp.unlink()
    tmp.symlink_to(cand.name)
    tmp.replace(link)
    return cand
