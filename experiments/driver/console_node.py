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

import collections
import contextlib
import dataclasses
import itertools
import json
import os
import queue
import subprocess
import threading
import time
import uuid
from collections.abc import Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import IO, Any

from dfrl.experiments.driver.console_command import CONSOLE_SCRIPT, console_command
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.tokens import env_with_tokens

__all__ = ["Address", "CONSOLE_SCRIPT", "ConsoleNode"]

Address = tuple[str, int]
"""A node's (host, port)."""

_STDERR_LINES = 200


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

    def __init__(self, tokens: int | str | Sequence[int | str] | None = None,
                 host: str = "127.0.0.1", port: int = 0, ready_timeout_s: float = 30.0,
                 log_path: Path | None = None, swipl: str | None = None,
                 tls: str | os.PathLike[str] | None = None) -> None:
        if tokens is None:
            tokens = []
        elif isinstance(tokens, (int, str)):
            tokens = [tokens]
        cmd = console_command(host, port, tls, swipl)
        env = env_with_tokens(tokens)   # never on the command line, which ps shows to all
        self._ids = itertools.count(1)
        self._cond = threading.Condition()
        self._replies: dict[Any, dict[str, Any]] = {}
        self._events: queue.Queue[dict[str, Any]] = queue.Queue()
        self._join_waiters: dict[str, queue.Queue[dict[str, Any]]] = {}
        self._stderr: collections.deque[str] = collections.deque(maxlen=_STDERR_LINES)
        self._write_lock = threading.Lock()
        self._eof = False
        self._address: Address | None = None
        self._log: IO[str] | None = open(log_path, "a", encoding="utf-8") if log_path else None
        self._proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                                      stderr=subprocess.PIPE, text=True, encoding="utf-8",
                                      bufsize=1, env=env)
        self._reader = threading.Thread(target=self._read_stdout, daemon=True,
                                        name="console-stdout")
        self._err_reader = threading.Thread(target=self._read_stderr, daemon=True,
                                            name="console-stderr")
        self._reader.start()
        self._err_reader.start()
        try:
            self._await_ready(ready_timeout_s)
        except BaseException:
            self.close()
            raise

    # -- reading ---------------------------------------------------------------------------
    def _read_stdout(self) -> None:
        assert self._proc.stdout is not None
        try:
            for line in self._proc.stdout:
                self._dispatch(line.rstrip("\n"))
        finally:
            with self._cond:
                self._eof = True
                self._cond.notify_all()

    def _read_stderr(self) -> None:
        assert self._proc.stderr is not None
        for line in self._proc.stderr:
            self._stderr.append(line.rstrip("\n"))
            if self._log is not None:
                self._log.write(line)
                self._log.flush()

    def _dispatch(self, line: str) -> None:
        try:
            msg = json.loads(line)
        except (ValueError, RecursionError):
            msg = None
        if not isinstance(msg, dict):
            if line.strip():
                self._events.put({"event": "unreadable", "line": line})
            return
        event = msg.get("event")
        if event is None and "id" in msg:
            with self._cond:
                self._replies[msg["id"]] = msg
                self._cond.notify_all()
        elif event == "ready":
            with self._cond:
                self._address = (str(msg["host"]), int(msg["port"]))
                self._cond.notify_all()
        else:
            request = msg.get("request")
            with self._cond:
                waiter = self._join_waiters.get(request) \
                    if event == "reply" and isinstance(request, str) else None
            (waiter or self._events).put(msg)

    def _await_ready(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while self._address is None and not self._eof:
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                self._cond.wait(left)
        if self._address is None:
            gone = "exited before it was ready" if self._eof else \
                f"did not report its address within {timeout_s} s"
            raise ExperimentError(f"the console node {gone} ({self._exit_text()})")

    def _exit_text(self) -> str:
        """The exit code and last stderr lines of a node that stopped answering."""
        try:
            code: int | None = self._proc.wait(timeout=2.0)
        except subprocess.TimeoutExpired:
            code = None
        if code is not None:
            self._err_reader.join(timeout=2.0)       # its last words
        return f"exit code {code}: {self.stderr_tail()}"

    # -- requests --------------------------------------------------------------------------
    def _request(self, op: str, timeout_s: float, **fields: Any) -> dict[str, Any]:
        """Send one request; return the reply's fields (without ``id`` and ``ok``)."""
        rid = next(self._ids)
        line = json.dumps({"id": rid, "op": op, **fields})
        self._send(line, op)
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while rid not in self._replies and not self._eof:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise ExperimentError(f"the console node did not answer {op} within "
                                          f"{timeout_s} s")
                self._cond.wait(left)
            reply = self._replies.pop(rid, None)
        if reply is None:
            raise ExperimentError(f"the console node exited during {op} "
                                  f"({self._exit_text()})")
        if not reply.get("ok"):
            raise ExperimentError(f"{op} failed: {reply.get('error', reply)}")
        return {k: v for k, v in reply.items() if k not in ("id", "ok")}

    def _send(self, line: str, op: str) -> None:
        stdin = self._proc.stdin
        if stdin is None or stdin.closed:
            raise ExperimentError(f"cannot send {op}: the console node is closed")
        try:
            with self._write_lock:
                stdin.write(line + "\n")
                stdin.flush()
        except (BrokenPipeError, OSError, ValueError) as exc:
            raise ExperimentError(f"cannot send {op} to the console node ({exc}; "
                                  f"{self._exit_text()})") from None

    @property
    def address(self) -> Address:
        """The console node's own (host, port)."""
        assert self._address is not None
        return self._address

    @property
    def pid(self) -> int:
        """Process id of the ``swipl`` process."""
        return self._proc.pid

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

    def control(self, first_stop: Address, agent: str, command: Mapping[str, Any],
                timeout_s: float = 30.0) -> dict[str, Any]:
        """Post a control command to ``agent`` at the node of its first stop.

        ``command`` is ``{"join": {"host", "port", "robot"}}``, ``{"method": name}`` or
        ``{"stop": True}``; the agent takes it at its next round start and acknowledges it
        with a ``control`` event in its round log. Returns ``{"agent", "command"}``
        (the command as the Prolog term posted).
        """
        host, port = first_stop
        return self._request("control", timeout_s, agent=agent, host=host, port=int(port),
                             command=dict(command))

    def load_program(self, program: str | Path, nodes: Sequence[Address],
                     timeout_s: float = 60.0) -> dict[str, Any]:
        """Load a Prolog program file into each of ``nodes``, in order (this node's tokens
        prove the right to). The first failure raises."""
        return self._request("load_program", timeout_s, program=str(Path(program).resolve()),
                             nodes=[[h, int(p)] for h, p in nodes])

    def agents_at(self, node: Address, timeout_s: float = 30.0) -> list[dict[str, Any]]:
        """The agents on ``node``: ``[{"name", "handler", "kind", "status"}, ...]``."""
        host, port = node
        return list(self._request("agents", timeout_s, node=[host, int(port)])["agents"])

    def robot(self, node: Address, request: str | Mapping[str, Any],
              timeout_s: float = 30.0) -> Any:
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
        return self._request("robot", timeout_s + 5.0, node=[host, int(port)], request=req,
                             wait_s=float(timeout_s))["result"]

    def request_join(self, driver: Address, robot_spec: Mapping[str, Any] | Any,
                     iterations: int | None = None, timeout_s: float = 60.0) -> dict[str, Any]:
        """Ask the driver whose console node is at ``driver`` to add a robot (``robot_spec``, a
        mapping or dataclass such as ``RobotSpec``, is passed on as a JSON object); wait for
        its answer and return the driver's result.

        Raises
        ------
        ExperimentError
            The request could not be posted, no answer came within ``timeout_s``, or the
            answer carries an ``error``.
        """
        spec = dataclasses.asdict(robot_spec) if dataclasses.is_dataclass(robot_spec) \
            else dict(robot_spec)
        request = uuid.uuid4().hex
        waiter: queue.Queue[dict[str, Any]] = queue.Queue()
        with self._cond:
            self._join_waiters[request] = waiter
        deadline = time.monotonic() + timeout_s
        try:
            self._request("join", timeout_s, to=list(driver), request=request, robot=spec,
                          iterations=iterations)
            try:
                event = waiter.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                raise ExperimentError(f"no answer to the join request from {driver[0]}:"
                                      f"{driver[1]} within {timeout_s} s") from None
        finally:
            with self._cond:
                del self._join_waiters[request]
        result = event.get("result")
        if not isinstance(result, dict):
            raise ExperimentError(f"unreadable answer to the join request: {event}")
        if "error" in result:
            raise ExperimentError(f"join refused: {result['error']}")
        return result

    def reply(self, to: Address, request: str | int, result: Mapping[str, Any],
              timeout_s: float = 30.0) -> None:
        """Answer the join request ``request`` that came from the console node ``to``
        (a ``join_request`` event's ``from``)."""
        self._request("reply", timeout_s, to=list(to), request=request, result=dict(result))

    def announce_program(self, driver: Address, program: str | Path,
                         timeout_s: float = 30.0) -> None:
        """Tell the driver whose console node is at ``driver`` that ``program`` was injected,
        so that it loads it into the robots that join later (a ``program`` event there)."""
        path = Path(program)
        self._request("program", timeout_s, to=list(driver), name=path.name,
                      text=path.read_text(encoding="utf-8"))

    # -- events ----------------------------------------------------------------------------
    def next_event(self, timeout_s: float) -> dict[str, Any] | None:
        """The next event the node reported, waiting at most ``timeout_s``; None if none came."""
        try:
            return self._events.get(timeout=max(0.0, timeout_s))
        except queue.Empty:
            return None

    def events(self) -> list[dict[str, Any]]:
        """The events reported so far and not yet taken (does not wait)."""
        taken = []
        while True:
            try:
                taken.append(self._events.get_nowait())
            except queue.Empty:
                return taken

    def stderr_tail(self, lines: int = 8) -> str:
        """The last lines the node wrote to stderr."""
        return "\n".join(list(self._stderr)[-lines:])

    @property
    def running(self) -> bool:
        """Whether the ``swipl`` process is still alive."""
        return self._proc.poll() is None

    # -- lifecycle -------------------------------------------------------------------------
    def close(self, timeout_s: float = 10.0) -> int:
        """Stop the node (``quit``, then end of input, then kill); return its exit code."""
        stdin = self._proc.stdin
        if self._proc.poll() is None and stdin is not None and not stdin.closed:
            # already gone: the exit code below tells
            with contextlib.suppress(BrokenPipeError, OSError, ValueError), self._write_lock:
                stdin.write(json.dumps({"id": "quit", "op": "quit"}) + "\n")
                stdin.flush()
        if stdin is not None and not stdin.closed:
            with contextlib.suppress(BrokenPipeError, OSError):
                stdin.close()
        try:
            code = self._proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            self._proc.kill()
            code = self._proc.wait(timeout=timeout_s)
        self._reader.join(timeout=timeout_s)
        self._err_reader.join(timeout=timeout_s)
        if self._log is not None and not self._err_reader.is_alive():
            self._log.close()
            self._log = None
        return code

    def __enter__(self) -> ConsoleNode:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
