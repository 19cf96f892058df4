"""Robots joining a running experiment: from the config's ``joins`` or asked for by
``dfrl join`` (a request file in ``RESULTS_DIR/join_requests/``)."""
from __future__ import annotations

from dfrl.experiments.config import JoinSpec, RobotSpec
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.launcher.agents import agent_name, send_control
from dfrl.experiments.launcher.children import await_ready
from dfrl.experiments.launcher.spawn import spawn, write_nodes
from dfrl.experiments.launcher.state import RunState
from dfrl.experiments.results.files import read_json

JOIN_REQUESTS = "join_requests"


def join_requests(state: RunState) -> list[tuple[JoinSpec, int | None]]:
    """Joins from the config, and requests left by ``dfrl join`` (bad ones said and removed)."""
    due: list[tuple[JoinSpec, int | None]] = [(j, None) for j in state.config.joins]
    req_dir = state.out / JOIN_REQUESTS
    if req_dir.is_dir():
        for f in sorted(req_dir.glob("*.json")):
            try:
                d = read_json(f)
                spec = JoinSpec(RobotSpec(**d["robot"]), after_round=0)
            except (ValueError, TypeError, KeyError) as exc:
                state.say(f"ignoring join request {f.name}: {exc}")
                f.unlink()
                continue
            if spec.robot.id in state.children and spec.robot.id not in state.joined:
                state.say(f"ignoring join request {f.name}: robot {spec.robot.id} exists")
                f.unlink()
                continue
            due.append((spec, d.get("iterations")))
    return due


def join(state: RunState, spec: JoinSpec, agent: str, remaining: int, done: int) -> None:
    """Start a joining robot's node and tell the agent (it adds the stop next round).

    Raises
    ------
    ExperimentError
        The node did not start or the agent could not be told.
    """
    rid = spec.robot.id
    state.joined.add(rid)
    child = spawn(state, spec.robot, remaining)
    await_ready([child])
    host, port = child.address
    stop = {"host": host, "port": port, "robot": rid}
    info = state.agents[agent]
    info.itinerary.append(stop)
    first = info.itinerary[0]
    send_control(first["host"], first["port"], state.config.token, agent, {"join": stop})
    write_nodes(state)
    state.say(f"robot {rid} ({spec.robot.arena}, {remaining} iterations) joins {agent} "
              f"after round {done}")


def handle_joins(state: RunState) -> None:
    """Start every join whose round has come (a failed join is said, the run goes on)."""
    c = state.config
    for spec, iterations in join_requests(state):
        rid = spec.robot.id
        if rid in state.joined:
            continue
        agent = agent_name(spec.robot.algo)
        log = state.logs.get(agent)
        if agent not in state.agents:
            state.say(f"robot {rid} cannot join: no agent for {spec.robot.algo}")
            state.joined.add(rid)
            continue
        if log is None or len(log.rounds) < spec.after_round or log.finished is not None:
            continue
        done = len(log.rounds)
        remaining = int(iterations) if iterations else max(1, c.iterations - done * c.respite)
        try:
            join(state, spec, agent, remaining, done)
        except (ExperimentError, OSError, ValueError) as exc:
            state.say(f"robot {rid} could not join: {exc}")
        req = state.out / JOIN_REQUESTS / f"{rid}.json"
        if req.exists():
            req.unlink()
