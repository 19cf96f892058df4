"""The suite's own report: the tests a marker expression left out (``-m 'not slow'`` by default,
pyproject.toml) are named at the end, not only counted, so that nobody mistakes the default
suite for the whole one. Works with pytest-xdist: each worker writes what it deselected into a
folder the controller made, and the controller reads it back."""

from __future__ import annotations

import shutil
import tempfile
from pathlib import Path
from typing import Any

import pytest

_KEY = "dfrl_deselected_dir"
_deselected: list[str] = []


def pytest_configure(config: pytest.Config) -> None:
    if not hasattr(config, "workerinput"):  # the controller (or a run without xdist)
        config._dfrl_deselected_dir = tempfile.mkdtemp(prefix="dfrl-deselected-")  # type: ignore[attr-defined]


def pytest_configure_node(node: Any) -> None:
    """xdist: tell each worker where to write what it deselected."""
    node.workerinput[_KEY] = node.config._dfrl_deselected_dir


def pytest_deselected(items: list[pytest.Item]) -> None:
    _deselected.extend(item.nodeid for item in items)


def pytest_collection_finish(session: pytest.Session) -> None:
    folder = getattr(session.config, "workerinput", {}).get(_KEY)
    if folder and _deselected:
        worker = session.config.workerinput.get("workerid", "w")  # type: ignore[attr-defined]
        Path(folder, f"{worker}.txt").write_text("\n".join(_deselected) + "\n")


def pytest_terminal_summary(terminalreporter: Any, exitstatus: int, config: pytest.Config) -> None:
    folder = getattr(config, "_dfrl_deselected_dir", None)
    if folder is None:
        return
    names = set(_deselected)
    for f in Path(folder).glob("*.txt"):
        names.update(line for line in f.read_text().splitlines() if line)
    shutil.rmtree(folder, ignore_errors=True)
    if not names:
        return
    marks, words = config.getoption("markexpr") or "", config.getoption("keyword") or ""
    how = ", ".join([f"-m {marks!r}"] * bool(marks) + [f"-k {words!r}"] * bool(words))
    terminalreporter.write_sep(
        "-",
        f"{len(names)} tests deselected ({how or 'by a plugin'}; "
        "the slow ones: scripts/test.sh -m slow runs them)",
    )
    for name in sorted(names):
        terminalreporter.write_line(f"deselected: {name}")
