"""Where the launcher starts agents and sends them control commands.

Both go through ``swipl`` scripts of :data:`dfrl.platform_pl.AGENTS_DIR` for now: one
``dfrl_launch.pl`` process per agent launch, one ``dfrl_control.pl`` process per command.
They sit behind these two functions so that a long-lived console node
(:mod:`dfrl.experiments.control`) can replace both in one place.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import Any

from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.results.files import write_json
from dfrl.platform_pl import AGENTS_DIR


def agent_name(algo: str) -> str:
    """The name of the dFRL agent that federates the robots learning with ``algo``."""
    return f"fed_{algo}"


def swipl_path() -> str:
    """The ``swipl`` executable.

    Raises
    ------
    ExperimentError
        SWI-Prolog is not installed.
    """
    path = shutil.which("swipl")
    if path is None:
        raise ExperimentError("swipl is not installed (run scripts/setup.sh)")
    return path


def launch_agent(launch: dict[str, Any], launch_file: Path, output_file: Path | None = None,
                 timeout_s: float = 60.0) -> None:
    """Create a dFRL itinerary agent and send it to its first stop.

    Parameters
    ----------
    launch : dict
        The launch plan (``name``, ``itinerary``, ``method``, ``rounds``, ``rest_s``,
        ``rounds_log``, ``token``, ``timeout_s``; see ``dfrl_launch.pl``), written to
        ``launch_file``.
    output_file : Path, optional
        Where the launcher script's stdout and stderr are kept.

    Raises
    ------
    ExperimentError
        The launch failed or timed out.
    """
    write_json(launch_file, launch)
    name = launch.get("name", "?")
    try:
        proc = subprocess.run([swipl_path(), "-q", str(AGENTS_DIR / "dfrl_launch.pl"),
                               str(launch_file)], capture_output=True, text=True,
                              timeout=timeout_s, cwd=launch_file.parent)
    except subprocess.TimeoutExpired:
        raise ExperimentError(f"launching agent {name} timed out after {timeout_s} s") from None
    if output_file is not None:
        output_file.parent.mkdir(parents=True, exist_ok=True)
        output_file.write_text(proc.stdout + proc.stderr, encoding="utf-8")
    if proc.returncode != 0:
        raise ExperimentError(f"launching agent {name} failed (exit {proc.returncode}): "
                              f"{(proc.stderr or proc.stdout).strip()}")


def send_control(host: str, port: int, token: int, agent: str, command: dict[str, Any],
                 timeout_s: float = 30.0) -> None:
    """Post a control command to agent ``agent``, whose first stop is host:port.

    ``command``: ``{"join": {"host", "port", "robot"}}``, ``{"method": name, "program": file,
    "nodes": [[host, port], ...]}`` or ``{"stop": true}`` (see ``dfrl_control.pl``); the
    agent's name is added as ``"agent"``.

    Raises
    ------
    ExperimentError
        The control script failed or timed out.
    """
    doc = {**command, "agent": agent}
    with tempfile.NamedTemporaryFile("w", suffix=".json", delete=False, encoding="utf-8") as fh:
        json.dump(doc, fh)
        cmd_file = fh.name
    try:
        proc = subprocess.run(
            [swipl_path(), "-q", str(AGENTS_DIR / "dfrl_control.pl"), str(host), str(port),
             str(token), cmd_file], capture_output=True, text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        raise ExperimentError(f"control command {doc} timed out after {timeout_s} s") from None
    finally:
        os.unlink(cmd_file)
    if proc.returncode != 0:
        raise ExperimentError(f"control command {doc} failed (exit {proc.returncode}): "
                              f"{(proc.stderr or proc.stdout).strip()}")
