"""Acting on a running experiment from another process: ``dfrl inject`` and ``dfrl join``."""
from __future__ import annotations

import dataclasses
import time
from pathlib import Path
from typing import Any

from dfrl.experiments.config import RobotSpec
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.launcher.agents import send_control
from dfrl.experiments.launcher.joins import JOIN_REQUESTS
from dfrl.experiments.results.files import read_json, write_json


def nodes_of(results_dir: str | Path) -> dict[str, Any]:
    """The ``nodes.json`` of a (running) experiment.

    Raises
    ------
    ExperimentError
        There is no ``nodes.json`` in ``results_dir``.
    """
    path = Path(results_dir) / "nodes.json"
    if not path.is_file():
        raise ExperimentError(f"{path} not found: is an experiment running there?")
    return read_json(path)


def inject_method(results_dir: str | Path, program: str | Path, method: str,
                  agent: str | None = None) -> list[str]:
    """Load ``program`` into every node of the running experiment and switch the agent(s) to
    ``method`` from their next round. Returns the agents told.

    Raises
    ------
    ExperimentError
        No such program or agent, or a control command failed.
    """
    info = nodes_of(results_dir)
    prog = Path(program).resolve()
    if not prog.is_file():
        raise ExperimentError(f"program {prog} not found")
    told = []
    for a in info["agents"]:
        if agent is not None and a["name"] != agent:
            continue
        nodes = [[s["host"], s["port"]] for s in a["itinerary"]]
        first = a["itinerary"][0]
        send_control(first["host"], first["port"], info["token"], a["name"],
                     {"method": method, "program": str(prog), "nodes": nodes})
        told.append(a["name"])
    if not told:
        raise ExperimentError(f"no agent {agent!r} in {results_dir}")
    return told


def join_robot(results_dir: str | Path, robot: str, arena: str, algo: str = "qlearning",
               iterations: int | None = None, seed: int | None = None,
               timeout_s: float = 60.0) -> dict[str, Any]:
    """Ask the launcher of a running experiment to start a robot and add it to the agent of
    its algorithm (from the agent's next round). Returns the new node's ``nodes.json`` entry.

    The launcher owns every process of an experiment: this leaves a request in
    ``RESULTS_DIR/join_requests/`` and waits until ``nodes.json`` lists the robot.

    Raises
    ------
    ExperimentError
        The robot exists already, or the launcher did not start it within ``timeout_s``.
    """
    info = nodes_of(results_dir)
    if any(n["robot"] == robot for n in info["nodes"]):
        raise ExperimentError(f"robot {robot} is already part of the experiment")
    spec = RobotSpec(robot, arena, algo, seed)
    req = {"robot": dataclasses.asdict(spec), "iterations": iterations}
    write_json(Path(results_dir) / JOIN_REQUESTS / f"{robot}.json", req)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        time.sleep(0.2)
        for n in nodes_of(results_dir)["nodes"]:
            if n["robot"] == robot:
                return n
    raise ExperimentError(f"the launcher did not start robot {robot} within {timeout_s} s "
                          "(is the experiment still running?)")
