"""The JSON-lines channel to a console node's ``swipl`` process: requests, replies, events.

:class:`ConsoleChannel` starts the process (:func:`dfrl.experiments.processes.start`, its own
process group), writes one request per line on its stdin and reads its stdout: a line with an
``id`` answers that request, ``{"event": "ready", ...}`` gives the node's address, and any
other line is an event, queued for :meth:`ConsoleChannel.next_event` (a ``reply`` event that a
caller waits for goes to that caller's queue instead, :meth:`ConsoleChannel.expect`).

Threading: two reader threads (stdout, stderr) and any number of callers. Replies, the address,
the end of input and the waiting queues are guarded by one condition; writes to stdin by a
lock; events go through a thread-safe queue.
"""

from __future__ import annotations

import collections
import contextlib
import itertools
import json
import queue
import subprocess
import threading
import time
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import IO, Any

from dfrl.experiments import processes
from dfrl.experiments.errors import ExperimentError

Address = tuple[str, int]
"""A node's (host, port)."""

_STDERR_LINES = 200


class ConsoleRequestError(ExperimentError):
    """The console node answered a request with an error: ``str()`` is its text;
    :attr:`formal_name` and :attr:`formal_args` the formal of the Prolog error term as the
    node sent it (``permission_error``, ``["access", "platform", "'10.0.0.7':7001"]``), empty
    when it sent none."""

    def __init__(self, text: str, formal: Any = None) -> None:
        super().__init__(text)
        formal = formal if isinstance(formal, dict) else {}
        self.formal_name = str(formal.get("name", ""))
        args = formal.get("args")
        self.formal_args = [str(a) for a in args] if isinstance(args, list) else []

    @property
    def token_refused(self) -> bool:
        """A platform accepted none of the tokens the console node proved
        (``permission_error(_, platform, Address)``, platform_pl/transport.pl)."""
        return (
            self.formal_name == "permission_error"
            and len(self.formal_args) == 3
            and self.formal_args[1] == "platform"
        )


class ConsoleChannel:
    """A ``swipl`` console process driven in JSON lines.

    Parameters
    ----------
    argv : sequence of str
        Its command line (:func:`~dfrl.experiments.driver.console.command.console_command`).
    env : mapping
        Its environment (with its tokens).
    ready_timeout_s : float
        How long to wait for the node to report its address.
    log_path : Path or None
        File that receives the node's stderr as well.

    Raises
    ------
    ExperimentError
        The process could not be started or did not report its address in time.
    """

    def __init__(
        self,
        argv: Sequence[str],
        env: Mapping[str, str],
        ready_timeout_s: float,
        log_path: Path | None = None,
    ) -> None:
        self._ids = itertools.count(1)
        self._cond = threading.Condition()
        self._replies: dict[Any, dict[str, Any]] = {}
        self._events: queue.Queue[dict[str, Any]] = queue.Queue()
        self._waiters: dict[str, queue.Queue[dict[str, Any]]] = {}
        self._stderr: collections.deque[str] = collections.deque(maxlen=_STDERR_LINES)
        self._write_lock = threading.Lock()
        self._eof = False
        self._address: Address | None = None
        self._log: IO[str] | None = open(log_path, "a", encoding="utf-8") if log_path else None
        try:
            self._proc = processes.start(
                argv,
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                env=env,
                bufsize=1,
            )
        except BaseException:
            if self._log is not None:
                self._log.close()
            raise
        self._reader = threading.Thread(
            target=self._read_stdout, daemon=True, name="console-stdout"
        )
        self._err_reader = threading.Thread(
            target=self._read_stderr, daemon=True, name="console-stderr"
        )
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
                waiter = (
                    self._waiters.get(request)
                    if event == "reply" and isinstance(request, str)
                    else None
                )
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
            gone = (
                "exited before it was ready"
                if self._eof
                else f"did not report its address within {timeout_s} s"
            )
            raise ExperimentError(f"the console node {gone} ({self._exit_text()})")

    def _exit_text(self) -> str:
        """The exit code and last stderr lines of a node that stopped answering."""
        try:
            code: int | None = self._proc.wait(timeout=2.0)
        except subprocess.TimeoutExpired:
            code = None
        if code is not None:
            self._err_reader.join(timeout=2.0)  # its last words
        return f"exit code {code}: {self.stderr_tail()}"

    # -- requests --------------------------------------------------------------------------
    def request(self, op: str, timeout_s: float, **fields: Any) -> dict[str, Any]:
        """Send one request; return the reply's fields (without ``id`` and ``ok``).

        Raises
        ------
        ExperimentError
            No answer within ``timeout_s``, the node exited, or it answered with an error.
        """
        rid = next(self._ids)
        self._send(json.dumps({"id": rid, "op": op, **fields}), op)
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while rid not in self._replies and not self._eof:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise ExperimentError(
                        f"the console node did not answer {op} within {timeout_s} s"
                    )
                self._cond.wait(left)
            reply = self._replies.pop(rid, None)
        if reply is None:
            raise ExperimentError(f"the console node exited during {op} ({self._exit_text()})")
        if not reply.get("ok"):
            raise ConsoleRequestError(
                f"{op} failed: {reply.get('error', reply)}", reply.get("formal")
            )
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
            raise ExperimentError(
                f"cannot send {op} to the console node ({exc}; {self._exit_text()})"
            ) from None

    @contextlib.contextmanager
    def expect(self, request: str) -> Iterator[queue.Queue[dict[str, Any]]]:
        """A queue that receives the ``reply`` events of ``request`` while the block runs."""
        waiter: queue.Queue[dict[str, Any]] = queue.Queue()
        with self._cond:
            self._waiters[request] = waiter
        try:
            yield waiter
        finally:
            with self._cond:
                del self._waiters[request]

    # -- what it is ------------------------------------------------------------------------
    @property
    def address(self) -> Address:
        """The node's own (host, port)."""
        assert self._address is not None
        return self._address

    @property
    def pid(self) -> int:
        return self._proc.pid

    @property
    def running(self) -> bool:
        return self._proc.poll() is None

    def next_event(self, timeout_s: float) -> dict[str, Any] | None:
        """The next event, waiting at most ``timeout_s``; None if none came."""
        try:
            return self._events.get(timeout=max(0.0, timeout_s))
        except queue.Empty:
            return None

    def events(self) -> list[dict[str, Any]]:
        """The events so far not yet taken (does not wait)."""
        taken = []
        while True:
            try:
                taken.append(self._events.get_nowait())
            except queue.Empty:
                return taken

    def stderr_tail(self, lines: int = 8) -> str:
        """The last lines the node wrote to stderr."""
        return "\n".join(list(self._stderr)[-lines:])

    # -- lifecycle -------------------------------------------------------------------------
    def close(self, timeout_s: float = 10.0) -> int | None:
        """Stop the node: ``quit``, then end of input, then :func:`~dfrl.experiments.processes.stop`
        after ``timeout_s``; return its exit code."""
        stdin = self._proc.stdin
        if self._proc.poll() is None and stdin is not None and not stdin.closed:
            # already gone: the exit code below tells
            with contextlib.suppress(BrokenPipeError, OSError, ValueError), self._write_lock:
                stdin.write(json.dumps({"id": "quit", "op": "quit"}) + "\n")
                stdin.flush()
        if stdin is not None and not stdin.closed:
            with contextlib.suppress(BrokenPipeError, OSError):
                stdin.close()
        processes.wait_or_stop(self._proc, timeout_s)
        self._reader.join(timeout=timeout_s)
        self._err_reader.join(timeout=timeout_s)
        if self._log is not None and not self._err_reader.is_alive():
            self._log.close()
            self._log = None
        return self._proc.returncode
