"""The experiment's console node: the driver's own platform node, a ``swipl`` child driven in
JSON lines. :class:`ConsoleNode` (:mod:`.node`) offers the requests; :mod:`.channel` carries
them to the process and back; :mod:`.command` is its command line."""

from __future__ import annotations

from dfrl.experiments.driver.console.command import CONSOLE_SCRIPT, console_command
from dfrl.experiments.driver.console.node import Address, ConsoleNode

__all__ = ["Address", "CONSOLE_SCRIPT", "ConsoleNode", "console_command"]
