"""Where the launcher starts agents and sends them control commands: through one long-lived
console node per experiment (:class:`dfrl.experiments.driver.console.ConsoleNode`, a ``swipl``
child driven in JSON lines), never one ``swipl`` process per command."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from dfrl.experiments.driver.console import ConsoleNode
from dfrl.experiments.tokens import Token

Address = tuple[str, int]


def agent_name(algo: str) -> str:
    """The name of the dFRL agent that federates the robots learning with ``algo``."""
    return f"fed_{algo}"


def open_console(
    token: Token | Sequence[Token],
    log_path: Path | None = None,
    host: str = "127.0.0.1",
    tls: str | Path | None = None,
) -> ConsoleNode:
    """Start the console node of an experiment at ``host`` (an address the robots reach; its
    token, handed over in its environment, lets it load programs into the robot processes, drive
    robot services, and its agents carry it); its stderr
    goes to ``log_path``. With ``tls`` (a node's TLS folder, ``dfrl certs node``) it speaks
    mutual TLS to every node (default: plaintext)."""
    if log_path is not None:
        log_path.parent.mkdir(parents=True, exist_ok=True)
    return ConsoleNode(tokens=token, host=host, log_path=log_path, tls=tls)


def launch_agent(console: ConsoleNode, launch: dict[str, Any], timeout_s: float = 60.0) -> None:
    """Create a dFRL itinerary agent on the console node and send it to its first stop.

    Parameters
    ----------
    launch : dict
        The launch plan (``name``, ``itinerary``, ``method``, ``rounds``, ``rest_s``,
        ``rounds_log``, ``timeout_s``; no ``token``: the agent carries the console's).

    Raises
    ------
    ExperimentError
        The launch failed or timed out.
    """
    console.launch_agent(launch, timeout_s=timeout_s)


def send_control(
    console: ConsoleNode,
    first_stop: Address,
    agent: str,
    command: dict[str, Any],
    program: str | Path | None = None,
    nodes: Sequence[Address] = (),
    timeout_s: float = 30.0,
) -> None:
    """Post a control command to ``agent`` at its first stop.

    ``command``: ``{"join": {"host", "port", "robot"}}``, ``{"method": name}`` or
    ``{"stop": True}``. With ``program``, the program is first loaded into each of ``nodes``
    (a new aggregation method must exist wherever the agent goes).

    Raises
    ------
    ExperimentError
        Loading the program or posting the command failed.
    """
    if program is not None:
        console.load_program(program, list(nodes), timeout_s=max(timeout_s, 60.0))
    console.control(first_stop, agent, command, timeout_s=timeout_s)
