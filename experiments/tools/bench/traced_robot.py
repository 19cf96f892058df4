"""A robot process that times the platform's steps: ``python -m
dfrl.experiments.tools.bench.traced_robot --config NODE.json``, what ``dfrl bench round --trace
DIR`` starts in place of :mod:`dfrl.experiments.robot_host`.

It is the robot process of :func:`dfrl.experiments.robot_host.process.main` with one probe
installed (:class:`StepTraceProbe`): the platform's steps are wrapped by ``step_trace.pl`` once
the platform is loaded, and the records go to ``DIR/robot-<id>.jsonl`` when the process closes
(``DIR`` from ``DFRL_STEP_TRACE``). The robot process itself knows no benchmark.
"""

from __future__ import annotations

import sys
from typing import Any

from dfrl.experiments.robot_host.config import RobotConfig
from dfrl.experiments.robot_host.process import main as robot_main
from dfrl.experiments.tools.bench.step_trace import PROLOG_FILE

MODULE = __name__
"""What a :class:`~dfrl.experiments.driver.launcher.children.RobotChild` runs with ``-m``."""


class StepTraceProbe:
    """Starts ``step_trace.pl`` in a robot process and writes its records at the end."""

    def started(self, bridge: Any, config: RobotConfig) -> None:
        from dfrl.pybridge import Atom

        bridge.call("use_module", Atom(str(PROLOG_FILE)))
        bridge.call("step_trace_start", module="step_trace")

    def closing(self, bridge: Any, config: RobotConfig) -> None:
        bridge.call("step_trace_write", f"robot-{config.robot}", module="step_trace")


if __name__ == "__main__":
    sys.exit(robot_main(probes=[StepTraceProbe()]))
