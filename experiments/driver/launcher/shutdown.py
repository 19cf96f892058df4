"""Stopping the robot nodes of an experiment, politely or not."""
from __future__ import annotations

import time

from dfrl.experiments.driver.launcher.state import RunState

#: Seconds all robot nodes together get to exit once told to stop.
SHUTDOWN_S = 15.0


def kill_all(state: RunState) -> None:
    """Kill every robot node now (on an exception or a signal)."""
    for ch in state.children.values():
        if ch.running:
            state.killed.add(ch.robot.id)
        ch.kill()


def shutdown(state: RunState) -> None:
    """Tell every node to stop, wait up to :data:`SHUTDOWN_S`, kill the ones left."""
    for ch in state.children.values():
        ch.close_stdin()
    deadline = time.monotonic() + SHUTDOWN_S
    for ch in state.children.values():
        if ch.running and not ch.stop(deadline - time.monotonic()):
            state.say(f"robot {ch.robot.id} did not exit; killing it")
            state.killed.add(ch.robot.id)
    for ch in state.children.values():
        ch.finish()
    state.check_children()
