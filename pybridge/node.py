"""A robot process: this Python process hosts a platform node and serves its robots' tables.

Threading model (see README.md): Prolog threads (agents, platform workers) never call
Python. ``read_table/3`` and friends post a request on a Prolog message queue; the robot's
control loop calls :meth:`Bridge.serve_pending` once per control step, in the Python main
thread, which answers the queued requests from the robot's numpy tables. So an agent sees a
consistent snapshot between two learning steps and no thread fights for the GIL.
"""

from __future__ import annotations

import atexit
import logging
import math
import os
import re
import threading
import warnings
from collections.abc import Sequence
from pathlib import Path
from typing import Any, ClassVar


from dfrl.pybridge.codec import Codec
from dfrl.pybridge.engine import Prolog, prolog
from dfrl.pybridge.errors import BridgeError, NodeStateError, PrologError, PrologFailure
from dfrl.pybridge.providers import TableProvider, provider_offer
from dfrl.pybridge.self_test import SelfTestReport, self_test
from dfrl.pybridge.serving import MODULE as _MODULE
from dfrl.pybridge.serving import RegisteredRobot, RequestServer, ServiceHandler, layout_term
from dfrl.pybridge.tartarus_commands import TartarusCommands
from dfrl.pybridge.terms import Atom, Term, Var, atom_or_self, robot_term

__all__ = ["TableProvider", "Bridge", "BRIDGE_FILE", "CODEC_FILE", "SERVICE_FILE", "SelfTestReport"]

log = logging.getLogger(__name__)

BRIDGE_FILE: Path = Path(__file__).resolve().parent / "robot_bridge.pl"
"""The Prolog side of the bridge (module ``robot_bridge``)."""

CODEC_FILE: Path = Path(__file__).resolve().parent / "table_codec.pl"
"""The Prolog side of the table codecs (module ``table_codec``)."""

SERVICE_FILE: Path = Path(__file__).resolve().parent / "robot_service.pl"
"""The ``dfrl_robot(...)`` platform requests of a robot service (module ``robot_service``)."""


class Bridge(TartarusCommands):
    """One robot process: embedded Prolog, the bridge, optionally the platform, and robots.

    Only one node may be open in a process at a time (the bridge's request queue is
    process-wide). Call :meth:`close` when done (it is also registered with ``atexit``).

    Parameters
    ----------
    request_timeout : float
        Default seconds an agent waits for the control loop to serve a table request
        (Prolog flag ``robot_bridge_timeout``).
    codec : Codec or str, optional
        Force ``"fts"`` or ``"text"``. By default ``fts`` is used if the start-up
        self-test passes, ``text`` otherwise.
    load_platform : bool
        Load the platform (``platform_pl/tartarus.pl``) right away.
    """

    _active: ClassVar[Bridge | None] = None
    _class_lock: ClassVar[threading.Lock] = threading.Lock()
    #: set when close() had to abort platform threads: the platform's own bookkeeping (its
    #: worker pools) no longer matches its threads, so it cannot run again in this process
    _platform_spent: ClassVar[bool] = False

    def __init__(
        self,
        *,
        request_timeout: float = 30.0,
        codec: Codec | str | None = None,
        load_platform: bool = False,
    ) -> None:
        with Bridge._class_lock:
            if Bridge._active is not None:
                raise NodeStateError("another Bridge is open in this process; close it first")
            Bridge._active = self
        self._closed = False
        self._nodes: list[Any] = []
        self._platform_loaded = False
        try:
            self.prolog: Prolog = prolog()
            self._must("use_module", Atom(str(BRIDGE_FILE)))
            self._must("use_module", Atom(str(CODEC_FILE)))
            self._server = RequestServer(self.prolog)
            self._robots = self._server.robots
            self.request_timeout = request_timeout
            self._must("bridge_attach_server", module=_MODULE)
            self.self_test_report = self.self_test()
            report = self.self_test_report
            if codec is None:
                chosen = Codec.FTS if report.fts_ok else Codec.TEXT
                if not report.fts_ok:
                    log.warning("fts codec self-test failed, using text: %s", report.detail)
            else:
                chosen = Codec(codec)
                if not (report.fts_ok if chosen is Codec.FTS else report.text_ok):
                    raise BridgeError(f"codec {chosen.value} failed its self-test: {report.detail}")
            self.codec = chosen
            if load_platform:
                self.load_platform()
        except BaseException:
            Bridge._active = None
            raise
        atexit.register(self.close)

    # -- properties ---------------------------------------------------------------------------
    @property
    def request_timeout(self) -> float:
        """Default seconds an agent waits for a table request to be served."""
        return float(self._must("current_prolog_flag", Atom("robot_bridge_timeout"), Var("T"))["T"])

    @request_timeout.setter
    def request_timeout(self, seconds: float) -> None:
        if not (isinstance(seconds, (int, float)) and math.isfinite(seconds) and seconds >= 0):
            raise ValueError("request_timeout must be a finite number >= 0")
        self._must("set_prolog_flag", Atom("robot_bridge_timeout"), float(seconds))

    @property
    def codec(self) -> Codec:
        """The value codec in use."""
        return self._codec

    @codec.setter
    def codec(self, value: Codec | str) -> None:
        value = Codec(value)
        if value is Codec.FTS and not self.self_test_report.fts_ok:
            raise BridgeError("the fts codec failed its self-test; it cannot be used")
        self._must("bridge_set_codec", Atom(value.value), module=_MODULE)
        self._codec = value
        self._server.codec = value

    @property
    def closed(self) -> bool:
        """True after :meth:`close`."""
        return self._closed

    # -- low level ----------------------------------------------------------------------------
    def _check_open(self) -> None:
        if self._closed:
            raise NodeStateError("this Bridge is closed")

    def _must(self, name: str, *args: Any, module: str | None = None) -> dict[str, Any]:
        sol = self.prolog.call(name, *args, module=module)
        if sol is None:
            raise PrologFailure(f"{module + ':' if module else ''}{name}/{len(args)} failed")
        return sol

    def call(self, name: str, *args: Any, module: str | None = None) -> dict[str, Any] | None:
        """Call ``module:name(args...)`` once with bound arguments (see :mod:`dfrl.pybridge.terms`).

        Returns the bindings of named :class:`Var` arguments, or ``None`` on failure.
        """
        self._check_open()
        return self.prolog.call(name, *args, module=module)

    def call_all(self, name: str, *args: Any, module: str | None = None) -> list[dict[str, Any]]:
        """All solutions of ``module:name(args...)``."""
        self._check_open()
        return self.prolog.call_all(name, *args, module=module)

    # -- codec self-test ----------------------------------------------------------------------
    def self_test(self) -> SelfTestReport:
        """Check both codecs against this SWI-Prolog, bit for bit, in both directions
        (see :mod:`dfrl.pybridge.self_test`)."""
        self._check_open()
        return self_test(self.prolog)

    # -- platform -----------------------------------------------------------------------------
    def load_platform(self, entry: str | Path | None = None) -> None:
        """Load the agent platform into this process (default ``platform_pl/tartarus.pl``).

        Raises
        ------
        NodeStateError
            If an earlier node of this process had to abort the platform's threads at
            :meth:`close` (its worker pools cannot be revived): use a new process.
        """
        self._check_open()
        if Bridge._platform_spent:
            raise NodeStateError(
                "the platform's threads were stopped by an earlier close() in "
                "this process; it cannot run again here (use a new process)"
            )
        if entry is None:
            from dfrl.platform_pl import ENTRY_POINT

            entry = ENTRY_POINT
        path = Path(entry)
        if not path.is_file():
            raise BridgeError(f"platform entry point {path} does not exist")
        self._must("ensure_loaded", Atom(str(path)))
        self._platform_loaded = True
        self._debug_topics(os.environ.get("DFRL_PL_DEBUG", ""))

    def _debug_topics(self, spec: str) -> None:
        """Turn on the Prolog debug topics of ``spec`` (``DFRL_PL_DEBUG``, e.g.
        ``dfrl(lease),dfrl(custody)``: ``name`` or ``name(arg)`` items, comma-separated),
        printed to stderr."""
        for item in re.findall(r"\w+(?:\(\w+\))?", spec):
            name, _, arg = item.rstrip(")").partition("(")
            topic = Term(name, Atom(arg)) if arg else Atom(name)
            if self.prolog.call("debug", topic) is None:
                log.warning("DFRL_PL_DEBUG: could not turn on debug topic %s", item)

    def start(self, host: str = "127.0.0.1", port: int = 0, **options: Any) -> Any:
        """Start a platform node listening on host:port (0: OS-chosen) in this process.

        Keyword options become Prolog options ``name(value)`` of ``node_start/3``
        (e.g. ``token=42``). Returns the node's name (e.g. ``Atom('127.0.0.1:40123')``).
        """
        self._check_open()
        if not self._platform_loaded:
            self.load_platform()
        opts = [Term(k, atom_or_self(v) if isinstance(v, str) else v) for k, v in options.items()]
        sol = self._must("node_start", Term(":", Atom(host), int(port)), Var("Node"), opts)
        node = sol["Node"]
        self._nodes.append(node)
        return node

    def join(self) -> Any:
        """Use the platform node already running in this process (started by other code, or
        by a consulted node file); return its name, or ``None`` if none runs. A node joined
        this way is not stopped by :meth:`close`."""
        self._check_open()
        if not self._platform_loaded:
            self.load_platform()
        try:
            sol = self.prolog.call("current_node", Var("Node"))
        except PrologError as exc:
            if isinstance(exc.formal, Term) and exc.formal.name == "existence_error":
                return None
            raise
        return sol["Node"] if sol else None

    def address(self, node: Any) -> tuple[Atom, int]:
        """(host, port) a platform node of this process listens on (e.g. from :meth:`start`)."""
        self._check_open()
        sol = self._must("node_property", node, Term("address", Var("A")))
        host, port = sol["A"].args
        return Atom(host), int(port)

    def start_tartarus(self, ip: str, port: int, token: int | None = None) -> Any:
        """Tartarus-style start: ``start_tartarus(Ip, Port[, Token])`` (port 0: OS-chosen).

        Returns the node's name; the node becomes the process's default platform.
        """
        self._check_open()
        if not self._platform_loaded:
            self.load_platform()
        if token is None:
            self._must("start_tartarus", Atom(ip), int(port))
        else:
            self._must("start_tartarus", Atom(ip), int(port), int(token))
        node = self._must("current_node", Var("Node"))["Node"]
        self._nodes.append(node)
        return node

    # -- robots -------------------------------------------------------------------------------
    def register_robot(
        self,
        robot_id: str | int,
        provider: Any,
        *,
        shape: Sequence[int] | None = None,
        algo: str | None = None,
        learner: str | None = None,
        algorithm: str | None = None,
    ) -> None:
        """Register a robot whose table or parameters agents on this node may read and write.

        What the robot offers is fixed here and told to agents in its props:
        ``learner(tabular|function)``, ``shape([S, A])`` for a Q-table, ``layout(L)`` for a
        parameter vector (``L = [Name-[D1, ...], ...]``).

        Parameters
        ----------
        robot_id : str or int
            The robot's id, an atom (str) or integer in Prolog.
        provider : TableProvider and/or ParamsProvider
            A tabular learner offers ``q_table`` (float64, shape (S, A)), ``visits``
            (int64, (S, A)), ``set_q_table(array)``; e.g. a
            :class:`dfrl.robots.training.Trainer` or a :class:`dfrl.pybridge.StaticTable`.
            A provider with ``params``, ``param_layout``, ``set_params`` and ``samples``
            (:class:`dfrl.pybridge.ParamsProvider`, e.g. :class:`dfrl.pybridge.StaticParams`)
            also offers its parameters; a function learner offers only those.
        shape : (int, int), optional
            (S, A): the shape of a tabular robot's table, fixed for the registration (every
            table write is checked against it). Give it: without it the provider's
            ``q_table`` is read once to learn it. A function learner has a table only as a
            view of its Q-function on a state grid (:class:`dfrl.robots.grid_view.GridView`),
            whose shape is given here.
        algo : str, optional
            The learner's registered name (``"qlearning"``, the default, ``"sarsa"``,
            ``"dqn"``, ...), given to agents in the robot's props as ``algo(Name)``.
        learner : {"tabular", "function"}, optional
            Default: the provider's ``learner_kind`` if it has one, else ``"tabular"``.
        algorithm : str, optional
            Deprecated name of ``algo`` (a :class:`DeprecationWarning`); still accepted.

        Raises
        ------
        TypeError
            The provider lacks what its learner kind must offer, or both ``algo`` and
            ``algorithm`` are given.
        ValueError
            A bad shape, layout or learner kind.
        """
        self._check_open()
        algo = _algo_keyword(algo, algorithm)
        rid = robot_term(robot_id)
        learner, table_shape, layout = provider_offer(provider, shape, learner)
        props = [Term("algo", Atom(algo))]
        if table_shape is not None:
            props.append(Term("shape", list(table_shape)))
        props.append(Term("learner", Atom(learner)))
        if layout is not None:
            props.append(Term("layout", layout_term(layout)))
        self._must("bridge_register_robot", rid, props, module=_MODULE)
        self._robots[rid] = RegisteredRobot(rid, provider, table_shape, algo, layout, learner)

    def unregister_robot(self, robot_id: str | int) -> None:
        """Forget a robot; later requests for it get ``existence_error(robot, Id)``."""
        self._check_open()
        rid = robot_term(robot_id)
        self._must("bridge_unregister_robot", rid, module=_MODULE)
        self._robots.pop(rid, None)

    def robots(self) -> list[tuple[Any, list[Any]]]:
        """(robot, props) for every robot registered in Prolog in this process."""
        self._check_open()
        sols = self.prolog.call_all("bridge_robot", Var("R"), Var("P"), module=_MODULE)
        return [(s["R"], s["P"]) for s in sols]

    # -- serving ------------------------------------------------------------------------------
    def serve_pending(self, max_requests: int = 16, timeout: float = 0.0) -> int:
        """Answer up to ``max_requests`` queued table requests; return how many.

        Call once per control step from the control loop (main thread). With the default
        ``timeout=0`` it never blocks; a positive timeout waits that long for the first
        request (useful when idle). A table write is validated here, where it enters
        Python (see :func:`dfrl.pybridge.serving.validate_write`).
        """
        self._check_open()
        return self._server.serve_pending(max_requests, timeout)

    def enable_service(self) -> None:
        """Load ``robot_service.pl`` (after the platform): this process's nodes then answer
        authenticated ``dfrl_robot(Request)`` platform requests, which
        :meth:`serve_service` hands to a Python handler."""
        self._check_open()
        if not self._platform_loaded:
            self.load_platform()
        self._must("use_module", Atom(str(SERVICE_FILE)))

    def serve_service(
        self, handler: ServiceHandler, max_requests: int = 4, timeout: float = 0.0
    ) -> int:
        """Answer up to ``max_requests`` queued ``dfrl_robot`` service requests with
        ``handler`` (request term -> reply term); return how many. Main thread only, like
        :meth:`serve_pending`; a positive ``timeout`` waits that long for the first one."""
        self._check_open()
        return self._server.serve_service(handler, max_requests, timeout)

    def node_value(self, node: Any, prop: str) -> Any:
        """The value of the platform node's property ``prop(Value)`` (e.g. ``id``,
        ``bind``), or ``None`` if the node has no such property."""
        self._check_open()
        sol = self.prolog.call("node_property", node, Term(prop, Var("V")))
        return sol["V"] if sol else None

    # -- shutdown -----------------------------------------------------------------------------
    def close(self, thread_timeout: float = 2.0) -> list[Any]:
        """Stop everything this node runs in Prolog, so that the interpreter exits cleanly.

        Unregisters the robots (waiting agents get ``existence_error(robot, R)``), stops
        the platform nodes it started, then aborts every other Prolog thread and joins
        those that are joinable (a detached thread frees itself).
        Returns the threads that did not stop within ``thread_timeout`` seconds (normally
        empty). Idempotent; also run at interpreter exit.
        """
        if self._closed:
            return []
        self._closed = True
        atexit.unregister(self.close)
        remaining: list[Any] = []
        try:
            for node in self._nodes:
                try:
                    self.prolog.call("node_stop", node)
                except BridgeError:
                    log.warning("stopping platform node %r failed", node, exc_info=True)
            self._nodes.clear()
            self._robots.clear()
            try:
                if (
                    self._platform_loaded
                    and self.prolog.call(
                        "current_predicate", Term("/", Atom("platform_shutdown"), 0)
                    )
                    is not None
                ):
                    self.prolog.call("platform_shutdown")  # the platform's own clean stop
            except BridgeError:
                log.warning("platform_shutdown/0 failed", exc_info=True)
            try:
                self.prolog.call("bridge_shutdown", module=_MODULE)
                sol = self.prolog.call(
                    "bridge_stop_threads",
                    float(thread_timeout),
                    Var("Left"),
                    Var("Aborted"),
                    module=_MODULE,
                )
                remaining = list(sol["Left"]) if sol else []
                aborted = sol["Aborted"] if sol else 0
                if self._platform_loaded and aborted:
                    Bridge._platform_spent = True
            except BridgeError:
                log.warning("closing the bridge failed", exc_info=True)
            if remaining:
                log.warning("Prolog threads still running after close(): %r", remaining)
        finally:
            with Bridge._class_lock:
                if Bridge._active is self:
                    Bridge._active = None
        return remaining

    def __enter__(self) -> Bridge:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self._closed else "open"
        return f"<Bridge {state} codec={self._codec.value} robots={list(self._robots)}>"


def _algo_keyword(algo: str | None, algorithm: str | None) -> str:
    """The learner's name given to :meth:`Bridge.register_robot`: ``algo``, else the deprecated
    keyword ``algorithm`` (with a :class:`DeprecationWarning`), else ``"qlearning"``."""
    if algorithm is None:
        return "qlearning" if algo is None else algo
    if algo is not None:
        raise TypeError("register_robot: give algo only (algorithm is its deprecated name)")
    warnings.warn(
        "register_robot(algorithm=...) is deprecated; use algo=...",
        DeprecationWarning,
        stacklevel=3,
    )
    return algorithm
