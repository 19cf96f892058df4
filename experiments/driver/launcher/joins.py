"""Robots joining a running experiment: from the config's ``joins``, or asked for by
``dfrl join`` through the platform (a ``join_request`` event of the experiment's console node,
answered with the new node's entry or an error)."""
from __future__ import annotations

from pathlib import Path
from typing import Any

from dfrl.experiments.driver.config import JoinSpec, RobotSpec
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.driver.launcher.agents import agent_name, send_control
from dfrl.experiments.driver.launcher.children import await_ready
from dfrl.experiments.driver.launcher.spawn import spawn, write_nodes
from dfrl.experiments.driver.launcher.state import RunState


def join(state: RunState, spec: JoinSpec, agent: str, remaining: int, done: int) -> dict[str, Any]:
    """Start a joining robot's node and tell the agent (it adds the stop next round).
    Returns the node's ``nodes.json`` entry.

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
    if state.programs and state.console is not None:   # methods injected before it joined
        for program in state.programs.values():
            state.console.load_program(program, [(host, port)])
    stop = {"host": host, "port": port, "robot": rid}
    info = state.agents[agent]
    info.itinerary.append(stop)
    first = info.itinerary[0]
    send_control(state.console, (first["host"], first["port"]), agent, {"join": stop})
    write_nodes(state)
    state.say(f"robot {rid} ({spec.robot.arena}, {remaining} iterations) joins {agent} "
              f"after round {done}")
    return {"robot": rid, "algo": spec.robot.algo, "arena": spec.robot.arena, "host": host,
            "port": port, "pid": child.pid, "node": spec.robot.robot_host, "joined": True}


def _due(state: RunState, spec: JoinSpec) -> tuple[str | None, str | None]:
    """(agent, None) when ``spec`` can join now, (None, why not) when it never can,
    (None, None) when its round has not come yet."""
    rid = spec.robot.id
    if rid in state.children:
        return None, f"robot {rid} is already part of the experiment"
    agent = agent_name(spec.robot.algo)
    if agent not in state.agents:
        return None, f"no agent for {spec.robot.algo}"
    log = state.logs.get(agent)
    if log is not None and log.finished is not None:
        return None, f"agent {agent} has finished"
    if log is None or len(log.rounds) < spec.after_round:
        return None, None
    return agent, None


def _start(state: RunState, spec: JoinSpec, agent: str, iterations: int | None) -> dict[str, Any]:
    c = state.config
    log = state.logs.get(agent)
    done = len(log.rounds) if log is not None else 0
    remaining = int(iterations) if iterations else max(1, c.iterations - done * c.respite)
    return join(state, spec, agent, remaining, done)


def handle_joins(state: RunState) -> None:
    """Start every config join whose round has come and answer every join request that came
    in (a failed join is said and answered; the run goes on)."""
    for spec in state.config.joins:
        if spec.robot.id in state.joined:
            continue
        agent, why = _due(state, spec)
        if why is not None:
            state.say(f"robot {spec.robot.id} cannot join: {why}")
            state.joined.add(spec.robot.id)
        elif agent is not None:
            try:
                _start(state, spec, agent, None)
            except (ExperimentError, OSError, ValueError) as exc:
                state.say(f"robot {spec.robot.id} could not join: {exc}")
    if state.console is None:
        return
    for event in state.console.events():
        if event.get("event") == "join_request":
            _answer(state, event)
        elif event.get("event") == "program":
            _keep_program(state, event)
        else:
            state.say(f"console node: {event}")


def _keep_program(state: RunState, event: dict[str, Any]) -> None:
    """A ``program`` event (``dfrl inject`` told us): keep the program in ``programs/`` of the
    results, to load it into every robot that joins from now on."""
    name, text = event.get("name"), event.get("text")
    if not (isinstance(name, str) and isinstance(text, str) and name.endswith(".pl")
            and name == Path(name).name and not name.startswith(".")):
        state.say(f"console node: unreadable program event {event.get('name')!r}")
        return
    path = state.out / "programs" / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    state.programs[name] = path
    state.say(f"program {name} injected; robots that join from now on load it too")


def _answer(state: RunState, event: dict[str, Any]) -> None:
    """Start the robot of a ``join_request`` event and reply to its sender."""
    try:
        spec = JoinSpec(RobotSpec(**event["robot"]), after_round=0)
        agent, why = _due(state, spec)
        if agent is None:
            raise ExperimentError(why or "not now")
        result: dict[str, Any] = _start(state, spec, agent, event.get("iterations"))
    except (ExperimentError, OSError, ValueError, TypeError, KeyError) as exc:
        state.say(f"join request refused: {exc}")
        result = {"error": str(exc)}
    try:
        state.console.reply(tuple(event["from"]), event["request"], result)
    except (ExperimentError, KeyError) as exc:
        state.say(f"could not answer a join request ({event}): {exc}")
