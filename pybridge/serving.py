"""Serving the agents' table and parameter requests from the robots' providers (Python main
thread).

:meth:`RequestServer.serve_pending` takes the requests that agents queued in Prolog
(``bridge_next_request/2``), answers each from the robot's provider and replies with
``bridge_reply/2``. A table write is validated here, once, where it enters Python
(:func:`validate_write`): registered shape, number of values, float values, finite values.
A parameter write likewise (:func:`validate_params`): registered layout, number of values,
float values, finite values. Providers receive only valid tables and vectors. A table is
read with the provider's ``read_table()`` and written with ``write_table(table, origin)``
(:func:`dfrl.pybridge.providers.read_table` and ``write_table``, which also serve providers
with the names of before); ``origin`` holds the write's origin (the agent's options
``round``, ``agent``, ``epoch``, ...; contract K4). A parameter write goes to a provider's
``set_params_from(vec, origin)``, else ``set_params(vec)`` (the origin dropped).

:meth:`RequestServer.serve_service` serves the host's own service queue the same way, with a
handler the host gives (``dfrl robot``'s ``dfrl_robot(...)`` requests, robot_service.pl).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from collections.abc import Callable
from typing import Any, cast

import numpy as np

from dfrl.pybridge import codec as _codec
from dfrl.pybridge.codec import Codec
from dfrl.pybridge.engine import Prolog
from dfrl.pybridge.errors import BridgeError, CodecError
from dfrl.pybridge.providers import (
    Layout,
    ParamsProvider,
    TableProvider,
    layout_size,
    read_table,
    write_table,
)
from dfrl.pybridge.terms import Atom, Term, Var

__all__ = [
    "RequestError",
    "RegisteredRobot",
    "RequestServer",
    "ServiceHandler",
    "validate_write",
    "validate_params",
    "layout_term",
    "write_origin",
]

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


def _write(provider: Any, setter: str, value: np.ndarray, origin: Any) -> None:
    """Apply a validated write: ``SETTER_from(value, origin)`` when the provider has it (it
    records where the write came from), else ``SETTER(value)``."""
    with_origin = getattr(type(provider), f"{setter}_from", None)
    if with_origin is not None:
        getattr(provider, f"{setter}_from")(value, write_origin(origin))
    else:
        getattr(provider, setter)(value)


def _note_read(provider: Any, what: str = "params_read") -> None:
    """Tell a provider that has ``params_read()`` that an agent read its parameters (its
    ``params`` property is a plain getter)."""
    note = getattr(type(provider), what, None)
    if note is not None:
        getattr(provider, what)()


@dataclass
class RegisteredRobot:
    """A robot this process serves: its provider and what it offers, fixed at registration.

    ``shape`` is the Q-table's (S, A), ``None`` for a robot without a table (a function
    learner); ``layout`` its parameter layout, ``None`` for a robot that offers no
    parameters; ``algo`` the learner's registered name (``"qlearning"``, ...); ``learner`` is
    ``"tabular"`` or ``"function"``.
    """

    robot_id: Any
    provider: TableProvider | ParamsProvider
    shape: tuple[int, int] | None
    algo: str
    layout: Layout | None = None
    learner: str = "tabular"

    @property
    def table_provider(self) -> TableProvider:
        """The provider's table side (``register_robot`` checked it has one if ``shape`` is
        set; :meth:`RequestServer._robot` asks for a shape first)."""
        return cast(TableProvider, self.provider)

    @property
    def params_provider(self) -> ParamsProvider:
        """The provider's parameter side (checked at registration if ``layout`` is set)."""
        return cast(ParamsProvider, self.provider)

    @property
    def layout_term(self) -> list[Term] | None:
        """The layout as the agents see it, ``[Name-[D1, ...], ...]`` (``None``: no params)."""
        return None if self.layout is None else layout_term(self.layout)


def layout_term(layout: Layout) -> list[Term]:
    """A layout as a Prolog term: ``[("w", (2, 3)), ("b", (3,))]`` -> ``[w-[2,3], b-[3]]``."""
    return [Term("-", Atom(name), [int(d) for d in shape]) for name, shape in layout]


def _decode_data(data: Any) -> np.ndarray:
    """The float64 vector in ``fts(String)`` / ``text(String)``."""
    if not (
        isinstance(data, Term)
        and data.arity == 1
        and isinstance(data.args[0], str)
        and data.name in (Codec.FTS.value, Codec.TEXT.value)
    ):
        raise BridgeError(f"malformed value data {data!r:.80}")
    try:
        return _codec.decode(Codec(data.name), data.args[0].encode("latin-1"))
    except (CodecError, ValueError) as exc:
        raise RequestError(Term("type_error", Atom("float_list"), str(exc))) from None


def _check_finite(values: np.ndarray) -> None:
    finite = np.isfinite(values)
    if not finite.all():
        bad = float(values[np.argmin(finite)])
        raise RequestError(Term("domain_error", Atom("finite_float"), bad))


def validate_write(shape: tuple[int, int], request_shape: Any, data: Any) -> np.ndarray:
    """Check a ``write_table`` request against the registered shape; return the table.

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
    values = _decode_data(data)
    n = shape[0] * shape[1]
    if values.size != n:
        raise RequestError(Term("domain_error", Term("qtable_size", n), int(values.size)))
    _check_finite(values)
    return values.reshape(shape)


def validate_params(layout: Layout, request_layout: Any, data: Any) -> np.ndarray:
    """Check a ``set_params`` request against the registered layout; return the vector.

    Parameters
    ----------
    layout : Layout
        The robot's registered layout.
    request_layout : Any
        The layout the agent sent (``[Name-[D1, ...], ...]`` when right).
    data : Term
        ``fts(String)`` or ``text(String)``: the encoded values.

    Returns
    -------
    np.ndarray
        float64, shape (layout_size(layout),), all finite.

    Raises
    ------
    RequestError
        ``domain_error(param_layout(Registered), Layout)``, ``type_error(float_list, Why)``
        (an fts element is not a float: the agent converts and asks again),
        ``domain_error(params_size(N), Len)`` or ``domain_error(finite_float, X)``.
    BridgeError
        Data that no agent side of the bridge sends.
    """
    registered = layout_term(layout)
    if request_layout != registered:
        raise RequestError(Term("domain_error", Term("param_layout", registered), request_layout))
    values = _decode_data(data)
    n = layout_size(layout)
    if values.size != n:
        raise RequestError(Term("domain_error", Term("params_size", n), int(values.size)))
    _check_finite(values)
    return values


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

    def serve_service(
        self, handler: ServiceHandler, max_requests: int = 4, timeout: float = 0.0
    ) -> int:
        """Answer up to ``max_requests`` queued service requests with ``handler``; return
        how many. A handler's :class:`RequestError` becomes ``error(Formal)``, any other
        exception ``error(python_error(Class, Message))``."""
        return self._serve_queue("bridge_next_service_request", handler, max_requests, timeout)

    def _serve_queue(
        self, next_pred: str, handler: ServiceHandler, max_requests: int, timeout: float
    ) -> int:
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
        if op.name == "read_params" and op.arity == 1:
            return self._params_reply(*self._params_robot(op.args[0]))
        if op.name == "write_params" and op.arity == 4:
            rid, layout, data, origin = op.args
            robot, robot_layout = self._params_robot(rid)
            vec = validate_params(robot_layout, layout, data)
            _write(robot.provider, "set_params", vec, origin)
            return Atom("ok")
        if op.name == "read_table" and op.arity == 1:
            return self._table_reply(read_table(self._robot(op.args[0])[0].table_provider))
        if op.name == "read_visits" and op.arity == 1:
            return self._table_reply(self._robot(op.args[0])[0].table_provider.visits)
        if op.name == "read_table_and_visits" and op.arity == 1:
            provider = self._robot(op.args[0])[0].table_provider
            visits = provider.visits
            return Term(
                "tables", self._table_reply(read_table(provider)), self._table_reply(visits)
            )
        if op.name == "write_table" and op.arity == 4:
            rid, shape, data, origin = op.args
            robot, robot_shape = self._robot(rid)
            table = validate_write(robot_shape, shape, data)
            write_table(robot.table_provider, table, write_origin(origin))
            return Atom("ok")
        raise BridgeError(f"unknown request {op!r}")

    def _registered(self, rid: Any) -> RegisteredRobot:
        robot = self.robots.get(rid)
        if robot is None:
            raise RequestError(Term("existence_error", Atom("robot"), rid))
        return robot

    def _robot(self, rid: Any) -> tuple[RegisteredRobot, tuple[int, int]]:
        """A registered robot with a Q-table, and the table's shape."""
        robot = self._registered(rid)
        if robot.shape is None:
            raise RequestError(Term("existence_error", Atom("qtable"), rid))
        return robot, robot.shape

    def _params_robot(self, rid: Any) -> tuple[RegisteredRobot, Layout]:
        """A registered robot that offers parameters, and their layout."""
        robot = self._registered(rid)
        if robot.layout is None:
            raise RequestError(Term("existence_error", Atom("params"), rid))
        return robot, robot.layout

    def _params_reply(self, robot: RegisteredRobot, layout: Layout) -> Term:
        provider = robot.params_provider
        vec = np.asarray(provider.params)
        n = layout_size(layout)
        if vec.shape != (n,):
            raise BridgeError(
                f"robot {robot.robot_id}'s parameters have shape {vec.shape}, "
                f"its layout says ({n},)"
            )
        samples = provider.samples
        if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or samples < 0:
            raise BridgeError(f"robot {robot.robot_id}'s samples is {samples!r}, not an int >= 0")
        data = _codec.encode(self.codec, vec.astype(np.float64, copy=False))
        reply = Term("params", robot.layout_term, int(samples), Term(self.codec.value, data))
        _note_read(provider, "params_read")
        return reply

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
