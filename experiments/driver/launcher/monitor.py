"""Following a running experiment: the agents' logs, the robots, joins, when to stop."""

from __future__ import annotations

import time

from dfrl.experiments.driver.config import ExperimentConfig
from dfrl.experiments.robot_host.config import Mode
from dfrl.experiments.driver.launcher.agent_roster import AgentRoster
from dfrl.experiments.driver.launcher.joins import Joins
from dfrl.experiments.driver.launcher.reporter import Reporter
from dfrl.experiments.driver.launcher.robot_roster import RobotRoster
from dfrl.experiments.driver.launcher.spawn import rest_s

#: Seconds between two status lines.
STATUS_PERIOD_S = 5.0


def status_line(robots: RobotRoster, agents: AgentRoster, reporter: Reporter) -> str:
    """Iterations per robot (``!``: crashed) and where each agent is."""
    crashed = robots.crashed()
    its = " ".join(
        f"{rid}:{it}" + ("!" if rid in crashed else "") for rid, it in robots.iterations().items()
    )
    return f"[{reporter.elapsed():6.1f} s] {its} | " + "; ".join(agents.where())


def monitor(
    config: ExperimentConfig,
    robots: RobotRoster,
    agents: AgentRoster,
    joins: Joins,
    reporter: Reporter,
) -> None:
    """Follow the run until the agents finished and the robots ended, or a limit passed."""
    c = config
    deadline = time.monotonic() - reporter.elapsed() + c.timeout_s
    robots_done_at: float | None = None
    finished_at: float | None = None
    last_status = 0.0
    while True:
        time.sleep(0.1)
        agents.read_logs(robots)
        robots.check()
        robots.show_progress()
        joins.handle()
        now = time.monotonic()
        if not reporter.quiet and now - last_status > STATUS_PERIOD_S:
            last_status = now
            reporter.say(status_line(robots, agents, reporter))
        if c.mode is Mode.SYNC and agents.infos() and agents.all_finished():
            # no more shares will come: robots past their last boundary exit by
            # themselves; one still waiting (a late joiner) is told to stop
            finished_at = finished_at or now
            if robots.all_exited() or now - finished_at > 2.0:
                return
        if robots.all_exited():
            agents.read_logs(robots)
            if agents.all_finished():
                return
            robots_done_at = robots_done_at or now
            if now - robots_done_at > 5.0:
                reporter.say("all robot processes ended before the agents finished")
                return
        elif robots.robots_done():
            robots_done_at = robots_done_at or now
            if agents.all_finished():
                return
            if now - robots_done_at > (
                60.0 if c.mode is Mode.SYNC else max(30.0, 3 * c.rounds * rest_s(c))
            ):
                reporter.say("robots finished but the agents did not; stopping")
                return
        if now > deadline:
            reporter.say(f"experiment timeout ({c.timeout_s} s): stopping")
            return
