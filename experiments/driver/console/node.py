"""A long-lived channel to running agents: the experiment's console node.

:class:`ConsoleNode` starts one ``swipl platform_pl/dfrl_agent/dfrl_console.pl`` process, a platform
node of its own, and talks to it in JSON lines over its stdin and stdout (the protocol is
documented in ``dfrl_console.pl``). Through it a driver launches dFRL agents, posts control
commands to a running agent's first stop (platform event ``dfrl_control/4``), loads programs
into running nodes, and exchanges join requests with other console nodes through the platform
(platform event ``dfrl_driver/3``) instead of files on a shared disk.

Requests are answered one at a time, in order. Events the node reports (join requests, replies,
injected programs, messages it could not read, and any stdout line that is not a JSON object, as
``{"event": "unreadable", "line": ...}``) are queued for :meth:`ConsoleNode.next_event`.
Every wait is bounded; every failure raises :class:`~dfrl.experiments.errors.ExperimentError`
with the node's own error text.

Example: ``with ConsoleNode(tokens=[1111]) as console: console.control(("127.0.0.1", 7001),
"fed_qlearning", {"method": "max"})`` (after ``console.launch_agent(plan)``).
"""

from __future__ import annotations

import dataclasses
import os
import queue
import time
import uuid
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any

from dfrl.experiments.driver.console.channel import Address, ConsoleChannel
from dfrl.experiments.driver.console.command import console_command
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.tokens import env_with_tokens

__all__ = ["Address", "ConsoleNode"]


class ConsoleNode:
    """A console platform node in a child ``swipl`` process, driven in JSON lines.

    Parameters
    ----------
    tokens : int, str, sequence of them, or None
        The node's tokens (it proves them when loading programs into other nodes), handed to
        the process in its environment (``DFRL_TOKEN``), never on its command line. None: an
        open node (it warns on loopback and refuses to start elsewhere).
    host : str
        Address to bind; also the host others reach it at.
    port : int
        Port to bind; 0 lets the OS choose (see :attr:`address`).
    ready_timeout_s : float
        How long to wait for the node to report its address.
    log_path : Path or None
        File that receives the node's stderr (warnings, errors) as well.
    swipl : str or None
        The ``swipl`` executable (default: found on ``PATH``).
    tls : path or None
        A node's TLS folder (``dfrl certs node``): mutual TLS on every connection, in and out
        (None: plaintext).

    Raises
    ------
    ExperimentError
        ``swipl`` is missing, ``tls`` lacks a file (a ``CertError``), or the node did not
        report its address in time (e.g. its TLS files do not make a context).
    """

    def __init__(
        self,
        tokens: int | str | Sequence[int | str] | None = None,
        host: str = "127.0.0.1",
        port: int = 0,
        ready_timeout_s: float = 30.0,
        log_path: Path | None = None,
        swipl: str | None = None,
        tls: str | os.PathLike[str] | None = None,
    ) -> None:
        if tokens is None:
            tokens = []
        elif isinstance(tokens, (int, str)):
            tokens = [tokens]
        cmd = console_command(host, port, tls, swipl)
        # the tokens go in its environment, never on the command line, which ps shows to all
        self._channel = ConsoleChannel(cmd, env_with_tokens(tokens), ready_timeout_s, log_path)

    def _request(self, op: str, timeout_s: float, **fields: Any) -> dict[str, Any]:
        return self._channel.request(op, timeout_s, **fields)

    @property
    def address(self) -> Address:
        """The console node's own (host, port)."""
        return self._channel.address

    @property
    def pid(self) -> int:
        """Process id of the ``swipl`` process."""
        return self._channel.pid

    def launch_agent(self, plan: Mapping[str, Any], timeout_s: float = 60.0) -> dict[str, Any]:
        """Create the dFRL agent of a launch plan on this node and move it to its first stop.

        Parameters
        ----------
        plan : mapping
            The launch plan (``name``, ``itinerary`` [{host, port, robot}, ...], ``method``,
            ``rounds``, ``rest_s``, ``rounds_log``, ``token``, ``timeout_s``).

        Returns
        -------
        dict
            ``{"agent": name, "host": host, "port": port}`` of the first stop, once it left.
        """
        return self._request("launch", timeout_s, plan=dict(plan))

    def control(
        self, first_stop: Address, agent: str, command: Mapping[str, Any], timeout_s: float = 30.0
    ) -> dict[str, Any]:
        """Post a control command to ``agent`` at the node of its first stop.

        ``command`` is ``{"join": {"host", "port", "robot"}}``, ``{"method": name}`` or
        ``{"stop": True}``; the agent takes it at its next round start and acknowledges it
        with a ``control`` event in its round log. Returns ``{"agent", "command"}``
        (the command as the Prolog term posted).
        """
        host, port = first_stop
        return self._request(
            "control", timeout_s, agent=agent, host=host, port=int(port), command=dict(command)
        )

    def load_program(
        self, program: str | Path, nodes: Sequence[Address], timeout_s: float = 60.0
    ) -> dict[str, Any]:
        """Load a Prolog program file into each of ``nodes``, in order (this node's tokens
        prove the right to). The first failure raises."""
        return self._request(
            "load_program",
            timeout_s,
            program=str(Path(program).resolve()),
            nodes=[[h, int(p)] for h, p in nodes],
        )

    def agents_at(self, node: Address, timeout_s: float = 30.0) -> list[dict[str, Any]]:
        """The agents on ``node``: ``[{"name", "handler", "kind", "status"}, ...]``."""
        host, port = node
        return list(self._request("agents", timeout_s, node=[host, int(port)])["agents"])

    def robot(
        self, node: Address, request: str | Mapping[str, Any], timeout_s: float = 30.0
    ) -> Any:
        """Send one request to the robot service (``dfrl robot``) at ``node``; its answer.

        Parameters
        ----------
        node : (str, int)
        request : str or mapping
            ``"status"``, ``"start"``, ``"stop"``, ``"files"``, ``{"configure": JSON_TEXT}`` or
            ``{"fetch": {"name": N, "offset": O, "max": M}}`` (contract K5).
        timeout_s : float
            Longest wait for the robot's answer (the console's own wait is a little longer).

        Returns
        -------
        Any
            ``status``: the status dict; ``files``: ``[{"name", "size"}, ...]``; ``fetch``:
            ``{"data": base64 text, "eof": bool}``; the others: ``True``.

        Raises
        ------
        ExperimentError
            The robot could not be reached, refused the request, or did not answer in time.
        """
        host, port = node
        req = request if isinstance(request, str) else dict(request)
        return self._request(
            "robot", timeout_s + 5.0, node=[host, int(port)], request=req, wait_s=float(timeout_s)
        )["result"]

    def request_join(
        self,
        driver: Address,
        robot_spec: Mapping[str, Any] | Any,
        iterations: int | None = None,
        timeout_s: float = 60.0,
    ) -> dict[str, Any]:
        """Ask the driver whose console node is at ``driver`` to add a robot (``robot_spec``, a
        mapping or dataclass such as ``RobotSpec``, is passed on as a JSON object); wait for
        its answer and return the driver's result.

        Raises
        ------
        ExperimentError
            The request could not be posted, no answer came within ``timeout_s``, or the
            answer carries an ``error``.
        """
        spec = (
            dict(robot_spec) if isinstance(robot_spec, Mapping) else dataclasses.asdict(robot_spec)
        )
        request = uuid.uuid4().hex
        deadline = time.monotonic() + timeout_s
        with self._channel.expect(request) as waiter:
            self._request(
                "join",
                timeout_s,
                to=list(driver),
                request=request,
                robot=spec,
                iterations=iterations,
            )
            try:
                event = waiter.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                raise ExperimentError(
                    f"no answer to the join request from {driver[0]}:"
                    f"{driver[1]} within {timeout_s} s"
                ) from None
        result = event.get("result")
        if not isinstance(result, dict):
            raise ExperimentError(f"unreadable answer to the join request: {event}")
        if "error" in result:
            raise ExperimentError(f"join refused: {result['error']}")
        return result

    def reply(
        self, to: Address, request: str | int, result: Mapping[str, Any], timeout_s: float = 30.0
    ) -> None:
        """Answer the join request ``request`` that came from the console node ``to``
        (a ``join_request`` event's ``from``)."""
        self._request("reply", timeout_s, to=list(to), request=request, result=dict(result))

    def announce_program(
        self, driver: Address, program: str | Path, timeout_s: float = 30.0
    ) -> None:
        """Tell the driver whose console node is at ``driver`` that ``program`` was injected,
        so that it loads it into the robots that join later (a ``program`` event there)."""
        path = Path(program)
        self._request(
            "program",
            timeout_s,
            to=list(driver),
            name=path.name,
            text=path.read_text(encoding="utf-8"),
        )

    # -- events and lifecycle ----------------------------------------------------------------
    def next_event(self, timeout_s: float) -> dict[str, Any] | None:
        """The next event the node reported, waiting at most ``timeout_s``; None if none came."""
        return self._channel.next_event(timeout_s)

    def events(self) -> list[dict[str, Any]]:
        """The events reported so far and not yet taken (does not wait)."""
        return self._channel.events()

    def stderr_tail(self, lines: int = 8) -> str:
        """The last lines the node wrote to stderr."""
        return self._channel.stderr_tail(lines)

    @property
    def running(self) -> bool:
        """Whether the ``swipl`` process is still alive."""
        return self._channel.running

    def close(self, timeout_s: float = 10.0) -> int | None:
        """Stop the node (``quit``, then end of input, then stop its process group); return
        its exit code."""
        return self._channel.close(timeout_s)

    def __enter__(self) -> ConsoleNode:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
