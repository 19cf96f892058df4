"""Serving the agents' table requests from the robots' providers (Python main thread).

:meth:`RequestServer.serve_pending` takes the requests that agents queued in Prolog
(``bridge_next_request/2``), answers each from the robot's provider and replies with
``bridge_reply/2``. A table write is validated here, once, where it enters Python
(:func:`validate_write`): registered shape, number of values, float values, finite values.
Providers receive only valid tables. A write's origin (the agent's options ``round``,
``agent``, ``epoch``, ...; contract K4) goes to a provider that defines
``set_q_table_from(table, origin)``, otherwise it is dropped and ``set_q_table(table)`` called.

:meth:`RequestServer.serve_service` serves the host's own service queue the same way, with a
handler the host gives (``dfrl robot``'s ``dfrl_robot(...)`` requests, robot_service.pl).
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, field
from collections.abc import Callable
from typing import Any

import numpy as np

from dfrl.pybridge import codec as _codec
from dfrl.pybridge.codec import Codec
from dfrl.pybridge.engine import Prolog
from dfrl.pybridge.errors import BridgeError, CodecError
from dfrl.pybridge.providers import TableProvider
from dfrl.pybridge.terms import Atom, Term, Var

__all__ = ["RequestError", "RegisteredRobot", "RequestServer", "ServiceHandler", "validate_write",
           "write_origin"]

#: Answers one service request: takes the request term, returns the reply term
#: (``ok(...)``, ``ok(json(Text))`` or ``error(Formal)``); may raise :class:`RequestError`.
ServiceHandler = Callable[[Any], Any]

log = logging.getLogger(__name__)

MODULE = "robot_bridge"


class RequestError(Exception):
    """Raised while serving a request; carries the Prolog formal term to reply with."""

    def __init__(self, formal: Any) -> None:
        super().__init__(formal)
        self.formal = formal


def _note_read(provider: Any) -> None:
    """Tell a provider that has ``table_read()`` that an agent read its Q-table (its
    ``q_table`` property is a plain getter)."""
    note = getattr(type(provider), "table_read", None)
    if note is not None:
        provider.table_read()


@dataclass
class RegisteredRobot:
    """A robot this process serves: its provider and the shape given at registration."""

    robot_id: Any
    provider: TableProvider
    shape: tuple[int, int]
    algorithm: str


def validate_write(shape: tuple[int, int], request_shape: Any, data: Any) -> np.ndarray:
    """Check a ``set_qtable`` request against the registered shape; return the table.

    Parameters
    ----------
    shape : (int, int)
        The robot's registered shape (S, A).
    request_shape : Any
        The shape the agent sent (a list ``[S, A]`` when right).
    data : Term
        ``fts(String)`` or ``text(String)``: the encoded values.

    Returns
    -------
    np.ndarray
        float64, C-contiguous, shape (S, A), all finite.

    Raises
    ------
    RequestError
        ``domain_error(shape(Registered), Shape)``, ``type_error(float_list, Why)`` (an fts
        element is not a float: the agent converts and asks again),
        ``domain_error(qtable_size(N), Len)`` or ``domain_error(finite_float, X)``.
    BridgeError
        Data that no agent side of the bridge sends.
    """
    if not (isinstance(request_shape, list) and tuple(request_shape) == tuple(shape)):
        raise RequestError(Term("domain_error", Term("shape", list(shape)), request_shape))
    if not (isinstance(data, Term) and data.arity == 1 and isinstance(data.args[0], str)
            and data.name in (Codec.FTS.value, Codec.TEXT.value)):
        raise BridgeError(f"malformed table data {data!r:.80}")
    try:
        values = _codec.decode(Codec(data.name), data.args[0].encode("latin-1"))
    except (CodecError, ValueError) as exc:
        raise RequestError(Term("type_error", Atom("float_list"), str(exc))) from None
    n = shape[0] * shape[1]
    if values.size != n:
        raise RequestError(Term("domain_error", Term("qtable_size", n), int(values.size)))
    finite = np.isfinite(values)
    if not finite.all():
        bad = float(values[np.argmin(finite)])
        raise RequestError(Term("domain_error", Atom("finite_float"), bad))
    return values.reshape(shape)


@dataclass
class RequestServer:
    """Answers queued table requests for the robots in :attr:`robots`.

    Parameters
    ----------
    prolog : Prolog
        The engine (calls from the main thread only).
    codec : Codec
        How replies are encoded (the node keeps it equal to Prolog's ``bridge_codec/1``).
    """

    prolog: Prolog
    codec: Codec = Codec.TEXT
    robots: dict[Any, RegisteredRobot] = field(default_factory=dict)

    def serve_pending(self, max_requests: int = 16, timeout: float = 0.0) -> int:
        """Answer up to ``max_requests`` queued requests; return how many (see
        :meth:`dfrl.pybridge.node.Bridge.serve_pending`)."""
        return self._serve_queue("bridge_next_request", self.serve, max_requests, timeout)

    def serve_service(self, handler: ServiceHandler, max_requests: int = 4,
                      timeout: float = 0.0) -> int:
        """Answer up to ``max_requests`` queued service requests with ``handler``; return
        how many. A handler's :class:`RequestError` becomes ``error(Formal)``, any other
        exception ``error(python_error(Class, Message))``."""
        return self._serve_queue("bridge_next_service_request", handler, max_requests, timeout)

    def _serve_queue(self, next_pred: str, handler: ServiceHandler, max_requests: int,
                     timeout: float) -> int:
        served = 0
        wait = float(timeout)
        while served < max_requests:
            sol = self.prolog.call(next_pred, Var("R"), wait, module=MODULE)
            if sol is None:
                break
            wait = 0.0
            req_id, op = sol["R"].args
            try:
                reply = handler(op)
            except RequestError as exc:
                reply = Term("error", exc.formal)
            except Exception as exc:  # noqa: BLE001 - every failure becomes a Prolog error
                log.debug("serving %r failed", op, exc_info=True)
                reply = _python_error(exc)
            except BaseException as exc:
                self.prolog.call("bridge_reply", req_id, _python_error(exc), module=MODULE)
                raise
            self.prolog.call("bridge_reply", req_id, reply, module=MODULE)
            served += 1
        return served

    def serve(self, op: Any) -> Any:
        """The reply to one request ``op`` (see the bridge's request protocol)."""
        if not isinstance(op, Term):
            raise BridgeError(f"unknown request {op!r}")
        if op.name == "get_qtable" and op.arity == 1:
            provider = self._robot(op.args[0]).provider
            reply = self._table_reply(provider.q_table)
            _note_read(provider)
            return reply
        if op.name == "get_visits" and op.arity == 1:
            return self._table_reply(self._robot(op.args[0]).provider.visits)
        if op.name == "get_qtable_and_visits" and op.arity == 1:
            provider = self._robot(op.args[0]).provider
            reply = Term("tables", self._table_reply(provider.q_table),
                         self._table_reply(provider.visits))
            _note_read(provider)
            return reply
        if op.name == "set_qtable" and op.arity == 4:
            rid, shape, data, origin = op.args
            robot = self._robot(rid)
            table = validate_write(robot.shape, shape, data)
            setter = getattr(type(robot.provider), "set_q_table_from", None)
            if setter is not None:
                robot.provider.set_q_table_from(table, write_origin(origin))
            else:
                robot.provider.set_q_table(table)
            return Atom("ok")
        raise BridgeError(f"unknown request {op!r}")

    def _robot(self, rid: Any) -> RegisteredRobot:
        robot = self.robots.get(rid)
        if robot is None:
            raise RequestError(Term("existence_error", Atom("robot"), rid))
        return robot

    def _table_reply(self, table: np.ndarray) -> Term:
        arr = np.asarray(table)
        if arr.ndim != 2:
            raise BridgeError(f"the robot's table has shape {arr.shape}, not 2-D")
        data = _codec.encode(self.codec, arr.astype(np.float64, copy=False))
        return Term("table", [int(arr.shape[0]), int(arr.shape[1])], Term(self.codec.value, data))


def write_origin(options: Any) -> dict[str, Any]:
    """The origin options of a table write as a dict: ``[round(3), agent(a)]`` ->
    ``{"round": 3, "agent": "a"}`` (atoms become ``str``; other entries are ignored)."""
    origin: dict[str, Any] = {}
    for item in options if isinstance(options, list) else []:
        if isinstance(item, Term) and item.arity == 1:
            value = item.args[0]
            origin[item.name] = str(value) if isinstance(value, Atom) else value
    return origin


def _python_error(exc: BaseException) -> Term:
    return Term("error", Term("python_error", Atom(type(exc).__qualname__), str(exc)))
