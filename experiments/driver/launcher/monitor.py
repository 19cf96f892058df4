"""Following a running experiment: the agents' logs, the robots, when to stop."""
from __future__ import annotations

import time

from dfrl.experiments.robot_host.config import Mode
from dfrl.experiments.driver.launcher.joins import handle_joins
from dfrl.experiments.driver.launcher.spawn import rest_s
from dfrl.experiments.driver.launcher.state import RunState
from dfrl.experiments.driver.results.agent_log import read_rounds_log

#: Seconds between two status lines.
STATUS_PERIOD_S = 5.0


def poll_logs(state: RunState) -> None:
    """Re-read every agent's log; say each round not said yet."""
    for name, info in state.agents.items():
        log = read_rounds_log(info.rounds_log, name)
        state.logs[name] = log
        shown = state.printed_rounds.get(name, 0)
        for rec in log.rounds[shown:]:
            its = " ".join(f"{rid}:{c.iteration}" for rid, c in state.children.items()
                           if c.robot.algo == info.algo)
            flags = "".join(f" SKIPPED {s.robot} ({' '.join(s.reason.split())[:120]})"
                            for s in rec.skipped)
            if rec.error:
                flags += f" METHOD FAILED, round aborted, no table written: {rec.error[:300]}"
            state.say(f"{name} round {rec.round}/{info.rounds} {rec.method} "
                      f"{rec.duration_ms:.0f} ms, {rec.hops} hops, visited "
                      f"{','.join(rec.visited) or 'none'}{flags} | {its}")
        state.printed_rounds[name] = len(log.rounds)


def status_line(state: RunState) -> str:
    """Iterations per robot (``!``: crashed) and where each agent is."""
    its = " ".join(f"{rid}:{c.iteration}" + ("!" if rid in state.crashed else "")
                   for rid, c in state.children.items())
    where = []
    for name, info in state.agents.items():
        log = state.logs.get(name)
        done = len(log.rounds) if log else 0
        at = state.agent_at.get(name)
        pos = f"{at[0]} ({at[1]})" if at else "-"
        st = "finished" if log and log.finished is not None else f"at {pos}"
        where.append(f"{name} {done}/{info.rounds} rounds, {st}")
    return f"[{time.monotonic() - state.t0:6.1f} s] {its} | " + "; ".join(where)


def monitor(state: RunState) -> None:
    """Follow the run until the agents finished and the robots ended, or a limit passed."""
    c = state.config
    deadline = state.t0 + c.timeout_s
    robots_done_at: float | None = None
    finished_at: float | None = None
    while True:
        time.sleep(0.1)
        poll_logs(state)
        state.check_children()
        state.view_samples()
        handle_joins(state)
        now = time.monotonic()
        if state.progress is not None and now - state.last_status > STATUS_PERIOD_S:
            state.last_status = now
            state.say(status_line(state))
        if c.mode is Mode.SYNC and state.agents and state.all_finished():
            # no more shares will come: robots past their last boundary exit by
            # themselves; one still waiting (a late joiner) is told to stop
            finished_at = finished_at or now
            if state.all_exited() or now - finished_at > 2.0:
                return
        if state.all_exited():
            poll_logs(state)
            if state.all_finished():
                return
            robots_done_at = robots_done_at or now
            if now - robots_done_at > 5.0:
                state.say("all robot processes ended before the agents finished")
                return
        elif state.robots_done():
            robots_done_at = robots_done_at or now
            if state.all_finished():
                return
            if now - robots_done_at > (60.0 if c.mode is Mode.SYNC else
                                       max(30.0, 3 * c.rounds * rest_s(state))):
                state.say("robots finished but the agents did not; stopping")
                return
        if now > deadline:
            state.say(f"experiment timeout ({c.timeout_s} s): stopping")
            return
