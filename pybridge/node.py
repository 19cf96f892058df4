"""A robot node: this Python process hosts a platform node and serves its robots' tables.

Threading model (see README.md): Prolog threads (agents, platform workers) never call
Python. ``get_qtable/2`` and friends post a request on a Prolog message queue; the robot's
control loop calls :meth:`RobotNode.serve_pending` once per control step, in the Python main
thread, which answers the queued requests from the robot's numpy tables. So an agent sees a
consistent snapshot between two learning steps and no thread fights for the GIL.
"""
from __future__ import annotations

import atexit
import logging
import math
import threading
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Protocol, runtime_checkable

import numpy as np

from dfrl.pybridge import codec as _codec
from dfrl.pybridge.codec import Codec
from dfrl.pybridge.engine import Prolog, prolog
from dfrl.pybridge.errors import BridgeError, CodecError, NodeStateError, PrologError, PrologFailure
from dfrl.pybridge.terms import Atom, Term, Var, atom_or_self

__all__ = ["TableProvider", "RobotNode", "Bridge", "BRIDGE_FILE", "SelfTestReport"]

log = logging.getLogger(__name__)

BRIDGE_FILE: Path = Path(__file__).resolve().parent / "robot_bridge.pl"
"""The Prolog side of the bridge (module ``robot_bridge``)."""

_MODULE = "robot_bridge"


@runtime_checkable
class TableProvider(Protocol):
    """What a robot offers to the bridge.

    ``q_table`` : float64 ndarray, shape (n_states, n_actions)
    ``visits`` : int64 ndarray, shape (n_states, n_actions)
    ``set_q_table(table)`` : replace the table with a float64 array of the same shape
    """

    @property
    def q_table(self) -> np.ndarray: ...

    @property
    def visits(self) -> np.ndarray: ...

    def set_q_table(self, table: np.ndarray) -> None: ...


@dataclass
class _Robot:
    robot_id: Any
    provider: TableProvider
    shape: tuple[int, int]
    algorithm: str


@dataclass(frozen=True)
class SelfTestReport:
    """Outcome of the start-up codec self-test."""

    fts_ok: bool
    text_ok: bool
    detail: str


class _RequestError(Exception):
    """Raised while serving a request; carries the Prolog formal term to reply with."""

    def __init__(self, formal: Any) -> None:
        super().__init__(formal)
        self.formal = formal


def _robot_term(robot_id: Any) -> Any:
    if isinstance(robot_id, bool) or not isinstance(robot_id, (str, int, np.integer)):
        raise TypeError(f"a robot id is a str or an int, not {type(robot_id).__name__}")
    return atom_or_self(robot_id) if isinstance(robot_id, str) else int(robot_id)


def _self_test_samples() -> list[np.ndarray]:
    rng = np.random.default_rng(20240611)
    special = np.array([0.0, -0.0, 1.0, -2.5, 0.1, 1 / 3, 5e-324, 2.2250738585072014e-308,
                        1.7976931348623157e308, -1e-300, 1e22, 123456.789e-12])
    return [
        np.empty(0),
        np.array([1.0]),
        special,                                        # varints of 1 byte
        rng.standard_normal(13) * 1e3,                  # 10*13+1 = 131: 2-byte varint
        rng.uniform(-1e6, 1e6, 1700),                   # 17001: 3-byte varint
    ]


class RobotNode:
    """One robot node: embedded Prolog, the bridge, optionally the platform, and robots.

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

    _active: ClassVar[RobotNode | None] = None
    _class_lock: ClassVar[threading.Lock] = threading.Lock()
    #: set when close() had to abort platform threads: the platform's own bookkeeping (its
    #: worker pools) no longer matches its threads, so it cannot run again in this process
    _platform_spent: ClassVar[bool] = False

    def __init__(self, *, request_timeout: float = 30.0, codec: Codec | str | None = None,
                 load_platform: bool = False) -> None:
        with RobotNode._class_lock:
            if RobotNode._active is not None:
                raise NodeStateError("another RobotNode is open in this process; close it first")
            RobotNode._active = self
        self._closed = False
        self._robots: dict[Any, _Robot] = {}
        self._nodes: list[Any] = []
        self._platform_loaded = False
        try:
            self.prolog: Prolog = prolog()
            self._must("use_module", Atom(str(BRIDGE_FILE)))
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
            RobotNode._active = None
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

    @property
    def closed(self) -> bool:
        """True after :meth:`close`."""
        return self._closed

    # -- low level ----------------------------------------------------------------------------
    def _check_open(self) -> None:
        if self._closed:
            raise NodeStateError("this RobotNode is closed")

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
        """Check both codecs against this SWI-Prolog, bit for bit, in both directions.

        The fts check first compares Prolog's own ``fast_term_serialized/2`` output with the
        Python encoder's bytes; only if they are identical are Python-made bytes given to
        Prolog to deserialize (malformed input would crash the process).
        """
        fts_ok, text_ok, notes = True, True, []
        for values in _self_test_samples():
            floats = [float(x) for x in values]
            bits = values.view(np.int64)
            if fts_ok:
                try:
                    made = self._must("fast_term_serialized", floats, Var("S"))["S"].encode("latin-1")
                    if made != _codec.encode_fts(values):
                        fts_ok = False
                        notes.append(f"fts bytes differ for {values.size} floats")
                    else:
                        back = self._must("fast_term_serialized", Var("L"), made)["L"]
                        if not np.array_equal(np.array(back, dtype=np.float64).view(np.int64), bits):
                            fts_ok = False
                            notes.append(f"fts read-back differs for {values.size} floats")
                        elif not np.array_equal(_codec.decode_fts(made).view(np.int64), bits):
                            fts_ok = False
                            notes.append(f"fts Python decode differs for {values.size} floats")
                except (BridgeError, UnicodeError) as exc:
                    fts_ok = False
                    notes.append(f"fts: {exc}")
            if text_ok:
                try:
                    ok = self._text_round_trip(values, floats)
                    if not ok:
                        text_ok = False
                        notes.append(f"text round trip differs for {values.size} floats")
                except (BridgeError, UnicodeError) as exc:
                    text_ok = False
                    notes.append(f"text: {exc}")
        if not text_ok:
            raise BridgeError("the text codec failed its self-test: " + "; ".join(notes))
        return SelfTestReport(fts_ok, text_ok, "; ".join(notes) or "ok")

    def _text_round_trip(self, values: np.ndarray, floats: list[float]) -> bool:
        bits = values.view(np.int64)
        # Prolog -> Python: the writer used by robot_bridge's text encoder
        sol = self._must("atomic_list_concat", floats, Atom(","), Var("A"))
        if not np.array_equal(_codec.decode_text(str(sol["A"])).view(np.int64), bits):
            return False
        # Python -> Prolog: the reader used by robot_bridge's text decoder
        data = _codec.encode_text(values)
        sol = self._must("decode_values", Term("text", data), Var("L"), module=_MODULE)
        return np.array_equal(np.array(sol["L"], dtype=np.float64).view(np.int64), bits)

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
        if RobotNode._platform_spent:
            raise NodeStateError("the platform's threads were stopped by an earlier close() in "
                                 "this process; it cannot run again here (use a new process)")
        if entry is None:
            from dfrl.platform_pl import ENTRY_POINT

            entry = ENTRY_POINT
        path = Path(entry)
        if not path.is_file():
            raise BridgeError(f"platform entry point {path} does not exist")
        self._must("ensure_loaded", Atom(str(path)))
        self._platform_loaded = True

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

    # Tartarus-style commands, always with bound arguments. Links are (Ip, Port) tuples.
    @staticmethod
    def _link(link: Sequence[Any]) -> tuple[Any, Any]:
        ip, port = link
        return (atom_or_self(ip), int(port))

    def create_mobile_agent(self, name: str | None, link: Sequence[Any], handler: str,
                            tokens: Iterable[int] = ()) -> Atom:
        """``create_mobile_agent(?Name, (Ip,Port), Handler, Tokens)``; returns the agent name."""
        self._check_open()
        name_arg: Any = Var("Name") if name is None else Atom(name)
        sol = self._must("create_mobile_agent", name_arg, self._link(link), Atom(handler), list(tokens))
        return Atom(sol["Name"]) if name is None else Atom(name)

    def create_static_agent(self, name: str | None, link: Sequence[Any], handler: str,
                            tokens: Iterable[int] = ()) -> Atom:
        """``create_static_agent(?Name, (Ip,Port), Handler, Tokens)``: an agent that never moves."""
        self._check_open()
        name_arg: Any = Var("Name") if name is None else Atom(name)
        sol = self._must("create_static_agent", name_arg, self._link(link), Atom(handler), list(tokens))
        return Atom(sol["Name"]) if name is None else Atom(name)

    def execute_agent(self, name: str, link: Sequence[Any], handler: str, event: Any = None) -> None:
        """``execute_agent(Name, (Ip,Port), Handler)``, or ``execute_agent/4`` with a start
        ``event`` other than ``main``."""
        self._check_open()
        if event is None:
            self._must("execute_agent", Atom(name), self._link(link), Atom(handler))
        else:
            self._must("execute_agent", Atom(name), self._link(link), Atom(handler), atom_or_self(event))

    def move_agent(self, name: str, link: Sequence[Any]) -> None:
        """``move_agent(Name, (Ip,Port))``."""
        self._check_open()
        self._must("move_agent", Atom(name), self._link(link))

    def purge_agent(self, name: str) -> None:
        """``purge_agent(Name)``."""
        self._check_open()
        self._must("purge_agent", Atom(name))

    def list_agents(self) -> list[Any]:
        """``list_agents(List)``: the agents on this platform."""
        self._check_open()
        return list(self._must("list_agents", Var("L"))["L"])

    def assert_file_to_tartarus(self, path: str | Path) -> None:
        """``assert_file_to_tartarus(File)``: load agent code into the running platform."""
        self._check_open()
        self._must("assert_file_to_tartarus", Atom(str(path)))

    def add_payload(self, name: str, predicates: Iterable[tuple[str, int]]) -> None:
        """``add_payload(Name, [(Pred,Arity), ...])``."""
        self._check_open()
        self._must("add_payload", Atom(name), [(Atom(p), int(a)) for p, a in predicates])

    def post_agent(self, target: str, link: Sequence[Any], args: Sequence[Any]) -> None:
        """``post_agent(Target, (Ip,Port), [Handler, Agent, Link | Args])``; ``args`` are
        converted as described in :mod:`dfrl.pybridge.terms`."""
        self._check_open()
        self._must("post_agent", Atom(target), self._link(link), list(args))

    # -- robots -------------------------------------------------------------------------------
    def register_robot(self, robot_id: str | int, provider: TableProvider, *,
                       algorithm: str = "qlearning") -> None:
        """Register a robot whose tables agents on this node may read and write.

        Parameters
        ----------
        robot_id : str or int
            The robot's id, an atom (str) or integer in Prolog.
        provider : TableProvider
            ``q_table`` (float64, shape (S, A)), ``visits`` (int64, (S, A)),
            ``set_q_table(array)``.
        algorithm : str
            Learning algorithm name, given to agents in the robot's props.
        """
        self._check_open()
        rid = _robot_term(robot_id)
        for attr in ("q_table", "visits", "set_q_table"):
            if not hasattr(provider, attr):
                raise TypeError(f"provider has no {attr!r}")
        table = np.asarray(provider.q_table)
        if table.ndim != 2 or 0 in table.shape:
            raise ValueError(f"q_table must be a non-empty 2-D array, got shape {table.shape}")
        shape = (int(table.shape[0]), int(table.shape[1]))
        props = [Term("algorithm", Atom(algorithm)), Term("shape", list(shape))]
        self._must("bridge_register_robot", rid, props, module=_MODULE)
        self._robots[rid] = _Robot(rid, provider, shape, algorithm)

    def unregister_robot(self, robot_id: str | int) -> None:
        """Forget a robot; later requests for it get ``existence_error(robot, Id)``."""
        self._check_open()
        rid = _robot_term(robot_id)
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
        request (useful when idle).
        """
        self._check_open()
        served = 0
        wait = float(timeout)
        while served < max_requests:
            sol = self.prolog.call("bridge_next_request", Var("R"), wait, module=_MODULE)
            if sol is None:
                break
            wait = 0.0
            request = sol["R"]
            req_id, op = request.args
            try:
                reply = self._serve(op)
            except _RequestError as exc:
                reply = Term("error", exc.formal)
            except Exception as exc:  # noqa: BLE001 - every failure becomes a Prolog error
                log.debug("serving %r failed", op, exc_info=True)
                reply = Term("error", Term("python_error", Atom(type(exc).__qualname__), str(exc)))
            except BaseException as exc:
                self.prolog.call("bridge_reply", req_id, Term("error", Term(
                    "python_error", Atom(type(exc).__qualname__), str(exc))), module=_MODULE)
                raise
            self.prolog.call("bridge_reply", req_id, reply, module=_MODULE)
            served += 1
        return served

    def _robot(self, rid: Any) -> _Robot:
        robot = self._robots.get(rid)
        if robot is None:
            raise _RequestError(Term("existence_error", Atom("robot"), rid))
        return robot

    def _table_reply(self, table: np.ndarray) -> Term:
        arr = np.asarray(table)
        if arr.ndim != 2:
            raise BridgeError(f"the robot's table has shape {arr.shape}, not 2-D")
        data = _codec.encode(self._codec, arr.astype(np.float64, copy=False))
        return Term("table", [int(arr.shape[0]), int(arr.shape[1])], Term(self._codec.value, data))

    def _serve(self, op: Any) -> Any:
        if not isinstance(op, Term):
            raise BridgeError(f"unknown request {op!r}")
        if op.name == "get_qtable" and op.arity == 1:
            return self._table_reply(self._robot(op.args[0]).provider.q_table)
        if op.name == "get_visits" and op.arity == 1:
            return self._table_reply(self._robot(op.args[0]).provider.visits)
        if op.name == "get_qtable_and_visits" and op.arity == 1:
            provider = self._robot(op.args[0]).provider
            return Term("tables", self._table_reply(provider.q_table), self._table_reply(provider.visits))
        if op.name == "set_qtable" and op.arity == 3:
            rid, shape, data = op.args
            robot = self._robot(rid)
            self._set(robot, shape, data)
            return Atom("ok")
        raise BridgeError(f"unknown request {op!r}")

    def _set(self, robot: _Robot, shape: Any, data: Any) -> None:
        current = robot.shape
        if not (isinstance(shape, list) and tuple(shape) == tuple(current)):
            raise _RequestError(Term("domain_error", Term("shape", list(current)), shape))
        if not (isinstance(data, Term) and data.arity == 1 and isinstance(data.args[0], str)):
            raise BridgeError(f"malformed table data {data!r:.80}")
        n = int(np.prod(current))
        try:
            values = _codec.decode(Codec(data.name), data.args[0].encode("latin-1"), expected=n)
        except (CodecError, ValueError) as exc:
            # not all floats: the agent side converts the values and asks again
            raise _RequestError(Term("type_error", Atom("float_list"), str(exc))) from None
        finite = np.isfinite(values)
        if not finite.all():
            bad = float(values[np.argmin(finite)])
            raise _RequestError(Term("domain_error", Atom("finite_float"), bad))
        robot.provider.set_q_table(values.reshape(current))

    # -- shutdown -----------------------------------------------------------------------------
    def close(self, thread_timeout: float = 2.0) -> list[Any]:
        """Stop everything this node runs in Prolog, so that the interpreter exits cleanly.

        Unregisters the robots (waiting agents get ``existence_error(robot, R)``), stops
        the platform nodes it started, then aborts and joins every other Prolog thread.
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
                if self._platform_loaded and self.prolog.call(
                        "current_predicate", Term("/", Atom("platform_shutdown"), 0)) is not None:
                    self.prolog.call("platform_shutdown")   # the platform's own clean stop
            except BridgeError:
                log.warning("platform_shutdown/0 failed", exc_info=True)
            try:
                self.prolog.call("bridge_shutdown", module=_MODULE)
                sol = self.prolog.call("bridge_stop_threads", float(thread_timeout), Var("Left"),
                                       Var("Aborted"), module=_MODULE)
                remaining = list(sol["Left"]) if sol else []
                aborted = sol["Aborted"] if sol else 0
                if self._platform_loaded and aborted:
                    RobotNode._platform_spent = True
            except BridgeError:
                log.warning("closing the bridge failed", exc_info=True)
            if remaining:
                log.warning("Prolog threads still running after close(): %r", remaining)
        finally:
            with RobotNode._class_lock:
                if RobotNode._active is self:
                    RobotNode._active = None
        return remaining

    def __enter__(self) -> RobotNode:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        state = "closed" if self._closed else "open"
        return f"<RobotNode {state} codec={self._codec.value} robots={list(self._robots)}>"
Bridge = RobotNode
"""Alias of :class:`RobotNode`."""
