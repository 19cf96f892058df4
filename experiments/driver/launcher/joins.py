"""Robots joining a running experiment: from the config's ``joins``, or asked for by
``dfrl join`` through the platform (a ``join_request`` event of the experiment's console node,
answered with the new node's entry or an error); and the programs ``dfrl inject`` gave the
driver, loaded into every robot that joins afterwards.

:class:`Joins` owns what it needs to remember (the joins handled, the programs); the
launcher's thread alone calls it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

from dfrl.experiments.driver.config import JoinSpec, RobotSpec
from dfrl.experiments.driver.config_check import check_robots
from dfrl.experiments.driver.launcher.agent_roster import AgentRoster
from dfrl.experiments.driver.launcher.agents import agent_name, send_control
from dfrl.experiments.driver.launcher.reporter import Reporter
from dfrl.experiments.driver.launcher.robot_roster import RobotRoster
from dfrl.experiments.driver.launcher.robots import await_ready
from dfrl.experiments.driver.launcher.spawn import Site, start_robot, write_nodes
from dfrl.experiments.errors import ExperimentError


#: Key paths of a join request as ``dfrl join`` names them.
_FLAGS = {
    "join.id": "--robot",
    "join.arena": "--arena",
    "join.algo": "--algo",
    "join.seed": "--seed",
    "join.robot_host": "--robot-host",
    "join": "join",
}


def check_join(
    entry: dict[str, Any], robot_ids: list[str], agent_algos: dict[str, str]
) -> list[str]:
    """Problems of a join request before anything is started: the robot entry checked as a
    config's (id, known algorithm, an arena that exists and parses, ``HOST:PORT``), its id
    free among ``robot_ids``, an agent learning with its algorithm (``agent_algos``: agent
    name -> algorithm). Each problem is named after the ``dfrl join`` option."""
    out = []
    for problem in check_robots([("join", entry)], resources=True):
        key, _, why = problem.partition(": ")
        out.append(f"{_FLAGS.get(key, key)}: {why}")
    rid, algo = entry.get("id"), entry.get("algo", "qlearning")
    if rid in robot_ids:
        out.append(f"--robot: robot {rid} is already part of the experiment")
    if not any(p.startswith("--algo") for p in out) and algo not in agent_algos.values():
        known = ", ".join(f"{n} ({a})" for n, a in agent_algos.items()) or "none"
        out.append(f"--algo: no agent of this experiment learns with {algo} (its agents: {known})")
    return out


class Joins:
    """Joins of one run (see the module doc)."""

    def __init__(
        self,
        site: Site,
        robots: RobotRoster,
        agents: AgentRoster,
        reporter: Reporter,
        placer: Callable[[str], str] | None = None,
    ) -> None:
        self._site = site
        self._placer = placer  # places a joiner elsewhere: its robot_host
        self._robots = robots
        self._agents = agents
        self._say = reporter.say
        self._handled: set[str] = set()  # config joins settled, robots that joined
        self._programs: dict[str, Path] = {}  # injected, for robots that join

    def handle(self) -> None:
        """Start every config join whose round has come and answer every join request that
        came in (a failed join is said and answered; the run goes on)."""
        for spec in self._site.config.joins:
            if spec.robot.id in self._handled:
                continue
            agent, why = self._due(spec)
            if why is not None:
                self._say(f"robot {spec.robot.id} cannot join: {why}")
                self._handled.add(spec.robot.id)
            elif agent is not None:
                try:
                    self._start(spec, agent, None)
                except (ExperimentError, OSError, ValueError) as exc:
                    self._say(f"robot {spec.robot.id} could not join: {exc}")
        for event in self._site.console.events():
            if event.get("event") == "join_request":
                self._answer(event)
            elif event.get("event") == "program":
                self._keep_program(event)
            else:
                self._say(f"console node: {event}")

    def _join(self, spec: JoinSpec, agent: str, remaining: int, done: int) -> dict[str, Any]:
        """Start a joining robot and tell the agent (it adds the stop next round). Returns the
        robot's ``nodes.json`` entry.

        Raises
        ------
        ExperimentError
            The robot did not start or the agent could not be told.
        """
        rid = spec.robot.id
        self._handled.add(rid)
        robot = None
        try:
            if self._placer is not None and spec.robot.robot_host is None:
                spec = replace(spec, robot=replace(spec.robot, robot_host=self._placer(rid)))
            robot = start_robot(
                self._site, spec.robot, remaining, self._agents, joins=len(self._handled)
            )
            self._robots.add(robot, joined=True)
            await_ready([robot])
        except (ExperimentError, OSError, ValueError) as exc:
            if robot is not None:
                robot.stop(0.0)
            self._robots.failed_join(rid, str(exc))  # a failed join, not a lost robot
            raise
        status = robot.status()
        assert status.address is not None
        host, port = status.address
        for program in self._programs.values():  # methods injected before it joined
            try:
                self._site.console.load_program(program, [(host, port)])
            except ExperimentError as exc:  # the robot joins; its stop lacks the method
                self._say(f"robot {rid}: injected program {program.name} did not load: {exc}")
        stop = {"host": host, "port": port, "robot": rid}
        first = self._agents.add_stop(agent, stop)
        send_control(self._site.console, (first["host"], first["port"]), agent, {"join": stop})
        write_nodes(self._site, self._robots, self._agents)
        self._say(
            f"robot {rid} ({spec.robot.arena}, {remaining} iterations) joins {agent} "
            f"after round {done}"
        )
        return {
            "robot": rid,
            "algo": spec.robot.algo,
            "arena": spec.robot.arena,
            "host": host,
            "port": port,
            "pid": status.pid,
            "robot_host": spec.robot.robot_host,
            "joined": True,
        }

    def _due(self, spec: JoinSpec) -> tuple[str | None, str | None]:
        """(agent, None) when ``spec`` can join now, (None, why not) when it never can,
        (None, None) when its round has not come yet."""
        rid = spec.robot.id
        if self._robots.has(rid):
            return None, f"robot {rid} is already part of the experiment"
        agent = agent_name(spec.robot.algo)
        if self._agents.get(agent) is None:
            return None, f"no agent for {spec.robot.algo}"
        log = self._agents.log(agent)
        if log is not None and log.finished is not None:
            return None, f"agent {agent} has finished"
        if log is None or len(log.rounds) < spec.after_round:
            return None, None
        return agent, None

    def _start(self, spec: JoinSpec, agent: str, iterations: int | None) -> dict[str, Any]:
        c = self._site.config
        done = self._agents.rounds_done(agent)
        remaining = int(iterations) if iterations else max(1, c.iterations - done * c.respite)
        return self._join(spec, agent, remaining, done)

    def _keep_program(self, event: dict[str, Any]) -> None:
        """A ``program`` event (``dfrl inject`` told us): keep the program in ``programs/`` of
        the results, to load it into every robot that joins from now on."""
        name, text = event.get("name"), event.get("text")
        if not (
            isinstance(name, str)
            and isinstance(text, str)
            and name.endswith(".pl")
            and name == Path(name).name
            and not name.startswith(".")
        ):
            self._say(f"console node: unreadable program event {event.get('name')!r}")
            return
        path = self._site.out / "programs" / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text, encoding="utf-8")
        self._programs[name] = path
        self._say(f"program {name} injected; robots that join from now on load it too")

    def _answer(self, event: dict[str, Any]) -> None:
        """Start the robot of a ``join_request`` event and reply to its sender."""
        try:
            entry = {k: v for k, v in dict(event["robot"]).items() if v is not None}
            problems = check_join(
                entry, list(self._robots.robots()), {a.name: a.algo for a in self._agents.infos()}
            )
            if problems:
                raise ExperimentError("; ".join(problems))
            spec = JoinSpec(RobotSpec(**event["robot"]), after_round=0)
            agent, why = self._due(spec)
            if agent is None:
                raise ExperimentError(why or "not now")
            result: dict[str, Any] = self._start(spec, agent, event.get("iterations"))
        except (ExperimentError, OSError, ValueError, TypeError, KeyError) as exc:
            self._say(f"join request refused: {exc}")
            result = {"error": str(exc)}
        try:
            self._site.console.reply(tuple(event["from"]), event["request"], result)
        except (ExperimentError, KeyError) as exc:
            self._say(f"could not answer a join request ({event}): {exc}")
