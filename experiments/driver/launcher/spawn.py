"""Starting the robot nodes and the agents of an experiment."""
from __future__ import annotations

import os
import time

from dfrl.experiments.driver.config import RobotSpec
from dfrl.experiments.robot_host.config import Mode, RobotConfig
from dfrl.experiments.driver.launcher.agents import agent_name, launch_agent
from dfrl.experiments.driver.launcher.children import RobotChild
from dfrl.experiments.driver.launcher.remote_robots import RemoteRobot
from dfrl.experiments.driver.launcher.state import AgentInfo, RunState
from dfrl.experiments.driver.results.files import write_json


def robot_seed(state: RunState, robot: RobotSpec) -> int:
    """A robot's seed: its own, its place in the config, or the next free one for a robot
    asked to join at runtime."""
    c = state.config
    known = [r.id for r in c.robots] + [j.robot.id for j in c.joins]
    if robot.seed is not None or robot.id in known:
        return c.robot_seed(robot)
    return c.seed + len(known) + len(state.joined)


def node_config(state: RunState, robot: RobotSpec, iterations: int) -> RobotConfig:
    """The configuration handed to a robot node process."""
    c = state.config
    grace = 10.0 if c.mode is Mode.SYNC else c.timeout_s
    return RobotConfig(robot=robot.id, out_dir=str(state.out), arena=robot.arena, algo=robot.algo,
                      seed=robot_seed(state, robot), iterations=iterations, respite=c.respite,
                      mode=c.mode, rtf=c.rtf, token=c.token, trainer=dict(c.trainer),
                      grace_s=grace, sync_timeout_s=max(60.0, c.timeout_s),
                      host=state.console_host,
                      eval_every=c.eval_every, eval_steps=c.eval_steps,
                      # a remote robot has its own TLS folder (dfrl robot --tls): not ours
                      tls=str(state.tls) if state.tls is not None and robot.robot_host is None
                      else None)


def spawn(state: RunState, robot: RobotSpec, iterations: int) -> RobotChild | RemoteRobot:
    """Start a robot: a node process on this host (not waiting for it), or, for a robot with
    a ``node``, configure and start the ``dfrl robot`` service there (waiting for it).

    Raises
    ------
    ExperimentError
        A remote robot could not be configured or started.
    """
    cfg = node_config(state, robot, iterations)
    if robot.robot_host is None:
        child: RobotChild | RemoteRobot = RobotChild(robot, cfg, state.out, state.on_event)
    else:
        assert state.console is not None
        child = RemoteRobot(robot, cfg, state.console, state.experiment_id)
        child.configure()
        child.start()
    state.children[robot.id] = child
    return child


def write_nodes(state: RunState) -> None:
    """``nodes.json``: the console node (where ``dfrl join`` asks), its TLS folder (null:
    plaintext), every node that is up and every agent; never the token (``secret.token``)."""
    nodes = [{"robot": rid, "algo": ch.robot.algo, "arena": ch.robot.arena,
              "host": ch.address[0], "port": ch.address[1], "pid": ch.pid,
              "node": ch.robot.robot_host, "joined": rid in state.joined}
             for rid, ch in state.children.items() if ch.address is not None]
    console = list(state.console.address) if state.console is not None else None
    write_json(state.out / "nodes.json", {"console": console,
                                          "tls": str(state.tls) if state.tls else None,
                                          "experiment": state.experiment_id,
                                          "nodes": nodes,
                                          "agents": [a.to_dict() for a in state.agents.values()]})


def control_dt(state: RunState) -> float:
    """Simulated seconds per iteration of the robots (the trainer's ``control_dt``)."""
    from dfrl.robots.training import TrainerConfig

    base = TrainerConfig().to_dict()
    base.update(state.config.trainer)
    return TrainerConfig.from_dict(base).sim.control_dt


def rest_s(state: RunState) -> float:
    """Seconds the agent rests at its first stop between rounds (async only)."""
    c = state.config
    if c.mode is Mode.SYNC:
        return 0.0
    if c.rest_s is not None:
        return float(c.rest_s)
    if c.rtf:
        return c.respite * control_dt(state) / c.rtf
    share = max(1.0, len(c.robots) / (os.cpu_count() or 1))
    return round(c.respite * 0.0005 * share, 3)


def await_first_respite(state: RunState, children: list[RobotChild | RemoteRobot]) -> None:
    """Async: wait until the agent's robots reach the first respite boundary, so that rounds
    fall near iterations respite, 2 x respite, ... (the agent rests in between)."""
    target = min(state.config.respite, state.config.iterations)
    deadline = time.monotonic() + state.config.timeout_s
    while time.monotonic() < deadline:
        state.check_children()
        if all(ch.iteration >= target or not ch.running for ch in children):
            return
        time.sleep(0.02)


def launch_agents(state: RunState) -> None:
    """One agent per algorithm, over the robots using it, in config order.

    Raises
    ------
    ExperimentError
        An agent could not be launched.
    """
    c = state.config
    for algo in c.algorithms():
        stops = [{"host": ch.address[0], "port": ch.address[1], "robot": rid}
                 for rid, ch in state.children.items() if ch.robot.algo == algo]
        if not stops:
            continue      # only joiners use it: nobody to start with
        name = agent_name(algo)
        if c.mode is Mode.ASYNC:
            await_first_respite(state, [state.children[s["robot"]] for s in stops])
        log_path = state.out / f"rounds_{name}.log"
        launch = {"name": name, "itinerary": stops, "method": c.method_for(algo),
                  "rounds": c.rounds, "rest_s": rest_s(state), "rounds_log": str(log_path),
                  # no token: the agent carries the console node's (the run's) tokens
                  "timeout_s": float(c.timeout_s),
                  # the agent posts its round log to the console node, which writes it here:
                  # no shared disk between the hosts the agent visits and the driver's
                  "log_to": list(state.console.address)}
        state.agents[name] = AgentInfo(name, algo, c.method_for(algo), c.rounds, str(log_path),
                                       list(stops))
        write_nodes(state)
        write_json(state.out / f"launch_{name}.json", launch)
        launch_agent(state.console, launch)
        state.say(f"agent {name} ({c.method_for(algo)}, {c.rounds} rounds) launched to "
                  f"{' -> '.join(s['robot'] for s in stops)}")
