"""Exceptions of the bridge: one root, Prolog errors kept as data."""

from __future__ import annotations

from typing import Any

__all__ = [
    "BridgeError",
    "PrologError",
    "PrologFailure",
    "TermConversionError",
    "CodecError",
    "NodeStateError",
]


class BridgeError(Exception):
    """Root of every error raised by :mod:`pybridge`."""


class PrologError(BridgeError):
    """A Prolog goal raised an exception.

    Attributes
    ----------
    term
        The exception term converted to Python (see :mod:`dfrl.pybridge.terms`), usually
        ``Term("error", formal, context)``. It is data, never a flattened string.
    """

    def __init__(self, term: Any, goal: str | None = None) -> None:
        self.term = term
        self.goal = goal
        super().__init__(term)

    @property
    def formal(self) -> Any:
        """The formal part of an ``error(Formal, Context)`` term, else the whole term."""
        from dfrl.pybridge.terms import Term

        if isinstance(self.term, Term) and self.term.name == "error" and len(self.term.args) == 2:
            return self.term.args[0]
        return self.term

    @property
    def context(self) -> Any:
        """The context part of an ``error(Formal, Context)`` term, else ``None``."""
        from dfrl.pybridge.terms import Term

        if isinstance(self.term, Term) and self.term.name == "error" and len(self.term.args) == 2:
            return self.term.args[1]
        return None

    def __str__(self) -> str:
        where = f" in {self.goal}" if self.goal else ""
        return f"Prolog exception{where}: {self.term!r}"


class PrologFailure(BridgeError):
    """A goal that must succeed (a command) failed."""


class TermConversionError(BridgeError, TypeError):
    """A Python value has no Prolog term form (or the reverse)."""


class CodecError(BridgeError, ValueError):
    """A table payload is malformed or does not match its announced shape."""


class NodeStateError(BridgeError, RuntimeError):
    """The node is used in a state that does not allow it (closed, another node open, ...)."""
