"""Acting on a running experiment from another process: ``dfrl inject`` and ``dfrl join``."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from dfrl.experiments.config import RobotSpec
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.launcher.agents import open_console, send_control
from dfrl.experiments.launcher.remote_robots import route_source
from dfrl.experiments.results.files import read_json


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
    targets = [a for a in info["agents"] if agent is None or a["name"] == agent]
    if not targets:
        raise ExperimentError(f"no agent {agent!r} in {results_dir}")
    first = targets[0]["itinerary"][0]
    with open_console(info["token"], host=route_source(first["host"], int(first["port"]))) \
            as console:
        for a in targets:
            nodes = [(s["host"], s["port"]) for s in a["itinerary"]]
            send_control(console, nodes[0], a["name"], {"method": method}, program=prog,
                         nodes=nodes)
    return [a["name"] for a in targets]


def join_robot(results_dir: str | Path, robot: str, arena: str, algo: str = "qlearning",
               iterations: int | None = None, seed: int | None = None,
               timeout_s: float = 60.0, node: str | None = None) -> dict[str, Any]:
    """Ask the launcher of a running experiment to start a robot and add it to the agent of
    its algorithm (from the agent's next round). Returns the new node's ``nodes.json`` entry.
    With ``node`` (``"HOST:PORT"`` of a running ``dfrl robot``) the launcher configures that
    service instead of starting a process.

    The launcher owns every process of an experiment: the request goes to its console node
    (``console`` in ``nodes.json``) as a platform post, and the launcher's answer comes back
    the same way.

    Raises
    ------
    ExperimentError
        The robot exists already, the launcher refused, or no answer came in ``timeout_s``.
    """
    info = nodes_of(results_dir)
    if any(n["robot"] == robot for n in info["nodes"]):
        raise ExperimentError(f"robot {robot} is already part of the experiment")
    if not info.get("console"):
        raise ExperimentError(f"{results_dir}/nodes.json names no console node to ask")
    spec = RobotSpec(robot, arena, algo, seed, node)
    driver = tuple(info["console"])
    with open_console(info["token"], host=route_source(driver[0], int(driver[1]))) as console:
        return console.request_join(tuple(info["console"]), spec, iterations,
                                    timeout_s=timeout_s)
