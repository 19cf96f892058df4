"""Starting the robots and the agents of an experiment, and the ``nodes.json`` that lists them."""

from __future__ import annotations

import os
import time
from collections.abc import Callable
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dfrl.experiments.driver.config import GRID, ExperimentConfig, RobotSpec
from dfrl.experiments.driver.console import ConsoleNode
from dfrl.experiments.driver.launcher.agent_roster import AgentInfo, AgentRoster
from dfrl.experiments.driver.launcher.agents import agent_name, launch_agent
from dfrl.experiments.driver.launcher.children import RobotChild
from dfrl.experiments.driver.launcher.remote_robots import RemoteRobot, StatusPoller
from dfrl.experiments.driver.launcher.reporter import Reporter
from dfrl.experiments.driver.launcher.robot_roster import RobotRoster
from dfrl.experiments.driver.launcher.robots import Robot
from dfrl.experiments.driver.results.files import write_json
from dfrl.experiments.robot_host.config import Mode, RobotConfig
from dfrl.robots.learners import learner_kind


#: How the agents reach a robot's platform node: (robot id, its node's (host, port)) -> the
#: (host, port) written into the itinerary. None (the default): the node's own address. A
#: benchmark sets it (in the thread that runs the launcher) to put a delaying proxy in front of
#: every node (``dfrl bench scale --delay-ms``).
STOP_ROUTE: ContextVar[Callable[[str, tuple[str, int]], tuple[str, int]] | None] = ContextVar(
    "stop_route", default=None
)


@dataclass(frozen=True)
class Site:
    """Where the robots of a run start and what they are told (fixed once its console node
    is up).

    Attributes
    ----------
    config : ExperimentConfig
        With its token.
    out : Path
        The results folder (absolute).
    console : ConsoleNode
        The run's console node.
    console_host : str
        Where the console node binds; the robot processes of this host bind there too.
    tls : Path or None
        TLS folder of the console node and of the robot processes of this host.
    experiment_id : str
        Robot hosts file the run's files under it.
    poller : StatusPoller
        Follows the robots on other hosts.
    """

    config: ExperimentConfig
    out: Path
    console: ConsoleNode
    console_host: str
    tls: Path | None
    experiment_id: str
    poller: StatusPoller


def robot_seed(config: ExperimentConfig, robot: RobotSpec, joins: int) -> int:
    """A robot's seed: its own, its place in the config, or the next free one for a robot
    asked to join at runtime (``joins``: joins handled so far, this one included)."""
    known = [r.id for r in config.robots] + [j.robot.id for j in config.joins]
    if robot.seed is not None or robot.id in known:
        return config.robot_seed(robot)
    return config.seed + len(known) + joins


#: Tree rounds a second a robot's node admits the copies of (a tree's copies are clones, and
#: a node admits 60 clones a minute by default, which let a tree run about one round every
#: 2 s: 70 of 100 fast rounds skipped robots with "Not enough resources: clones").
TREE_ROUNDS_PER_S = 20


def clone_limit(c: ExperimentConfig) -> int | None:
    """The clone limit of the robots' nodes: None (the platform's) for a chain; for a tree,
    ``fanout`` clones per round at :data:`TREE_ROUNDS_PER_S` rounds a second."""
    return c.fanout * TREE_ROUNDS_PER_S * 60 if c.itinerary == "tree" else None


def robot_config(site: Site, robot: RobotSpec, iterations: int, joins: int = 0) -> RobotConfig:
    """The configuration a robot runs."""
    c = site.config
    grace = 10.0 if c.mode is Mode.SYNC else c.timeout_s
    return RobotConfig(
        robot=robot.id,
        out_dir=str(site.out),
        arena=robot.arena,
        algo=robot.algo,
        seed=robot_seed(c, robot, joins),
        iterations=iterations,
        respite=c.respite,
        mode=c.mode,
        rtf=c.rtf,
        token=c.token,
        trainer=dict(c.trainer),
        grace_s=grace,
        sync_timeout_s=max(60.0, c.timeout_s),
        host=site.console_host,
        eval_every=c.eval_every,
        eval_steps=c.eval_steps,
        clone_limit=clone_limit(c),
        learners=dict(c.learners),
        # a remote robot has its own TLS folder (dfrl robot --tls): not ours
        tls=None if site.tls is None or robot.robot_host is not None else str(site.tls),
    )


def start_robot(
    site: Site, robot: RobotSpec, iterations: int, agents: AgentRoster, joins: int = 0
) -> Robot:
    """Start a robot: a process on this host (not waiting for it to come up), or, for a robot
    with a ``robot_host``, the ``dfrl robot`` service there (configured and started).

    Raises
    ------
    ExperimentError
        The robot could not be started.
    """
    cfg = robot_config(site, robot, iterations, joins)
    started: Robot
    algo = robot.algo

    def on_event(rid: str, op: str, iteration: int) -> None:
        agents.on_hop(rid, algo, op, iteration)

    if robot.robot_host is None:
        started = RobotChild(robot, cfg, site.out, on_event=on_event)
    else:
        started = RemoteRobot(
            robot, cfg, site.console, site.experiment_id, site.poller, on_event=on_event
        )
    started.start()
    return started


def write_nodes(site: Site, robots: RobotRoster, agents: AgentRoster) -> None:
    """``nodes.json``: the console node (where ``dfrl join`` asks), its TLS folder (null:
    plaintext), every robot that is up and every agent; never the token (``secret.token``)."""
    nodes = []
    for rid, robot in robots.robots().items():
        status = robot.status()
        if status.address is not None:
            nodes.append(
                {
                    "robot": rid,
                    "algo": robot.spec.algo,
                    "arena": robot.spec.arena,
                    "host": status.address[0],
                    "port": status.address[1],
                    "pid": status.pid,
                    "robot_host": robot.spec.robot_host,
                    "joined": robots.joined(rid),
                }
            )
    write_json(
        site.out / "nodes.json",
        {
            "console": list(site.console.address),
            "tls": str(site.tls) if site.tls else None,
            "experiment": site.experiment_id,
            "nodes": nodes,
            "agents": [a.to_dict() for a in agents.infos()],
        },
    )


def control_dt(config: ExperimentConfig) -> float:
    """Simulated seconds per iteration of the robots (the trainer's ``control_dt``)."""
    from dfrl.robots.training import TrainerConfig  # pybullet: only when asked

    base = TrainerConfig().to_dict()
    base.update(config.trainer)
    return TrainerConfig.from_dict(base).sim.control_dt


def rest_s(config: ExperimentConfig) -> float:
    """Seconds the agent rests at its first stop between rounds (async only)."""
    if config.mode is Mode.SYNC:
        return 0.0
    if config.rest_s is not None:
        return float(config.rest_s)
    if config.rtf:
        return config.respite * control_dt(config) / config.rtf
    share = max(1.0, len(config.robots) / (os.cpu_count() or 1))
    return round(config.respite * 0.0005 * share, 3)


def await_first_respite(config: ExperimentConfig, robots: RobotRoster, ids: list[str]) -> None:
    """Async: wait until the robots ``ids`` reach the first respite boundary, so that rounds
    fall near iterations respite, 2 x respite, ... (the agent rests in between)."""
    target = min(config.respite, config.iterations)
    deadline = time.monotonic() + config.timeout_s
    while time.monotonic() < deadline:
        robots.check()
        statuses = robots.statuses()
        if all(statuses[r].iteration >= target or not statuses[r].running for r in ids):
            return
        time.sleep(0.02)


def launch_agents(site: Site, robots: RobotRoster, agents: AgentRoster, reporter: Reporter) -> None:
    """One agent per algorithm, over the robots using it, in config order; an agent of a
    function learner (``dfrl.robots.learners.learner_kind``: ``linear``, ``dqn``) carries
    parameter vectors (launch plan ``"carries": "params"``), the others Q-tables. In a grid
    federation (``config.federation``) one agent, ``fed_grid``, carries Q-tables over every
    robot (``ExperimentConfig.agent_groups``).

    Raises
    ------
    ExperimentError
        An agent could not be launched.
    """
    c = site.config
    route = STOP_ROUTE.get()
    for algo, algos in c.agent_groups():
        stops: list[dict[str, Any]] = []
        for rid, robot in robots.robots().items():
            address = robot.status().address
            if robot.spec.algo in algos and address is not None:
                host, port = (
                    route(rid, (str(address[0]), int(address[1]))) if route is not None else address
                )
                stops.append({"host": host, "port": port, "robot": rid})
        if not stops:
            continue  # only joiners use it: nobody to start with
        name = agent_name(algo)
        if c.mode is Mode.ASYNC:
            await_first_respite(c, robots, [s["robot"] for s in stops])
        log_path = site.out / f"rounds_{name}.log"
        launch = {
            "name": name,
            "itinerary": stops,
            "method": c.method_for(algo),
            "rounds": c.rounds,
            "rest_s": rest_s(c),
            "rounds_log": str(log_path),
            # no token: the agent carries the console node's (the run's) tokens
            "timeout_s": float(c.timeout_s),
            "skip_after_s": float(c.skip_after_s),
            # the agent posts its round log to the console node, which writes it here:
            # no shared disk between the hosts the agent visits and the driver's
            "log_to": list(site.console.address),
        }
        if c.itinerary != "chain":
            launch["itinerary_kind"] = c.itinerary  # tree: clones over the robots
            launch["fanout"] = c.fanout
        if algo != GRID and learner_kind(algo) == "function":
            launch["carries"] = "params"  # linear, dqn: FedAvg of parameter vectors
        agents.add(
            AgentInfo(
                name,
                algo,
                c.method_for(algo),
                c.rounds,
                str(log_path),
                tuple(stops),
                c.itinerary,
                c.fanout,
            )
        )
        write_nodes(site, robots, agents)
        write_json(site.out / f"launch_{name}.json", launch)
        launch_agent(site.console, launch)
        reporter.say(
            f"agent {name} ({c.method_for(algo)}, {c.rounds} rounds) launched to "
            f"{' -> '.join(s['robot'] for s in stops)}"
        )
