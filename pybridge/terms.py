"""Python values that stand for Prolog terms.

The mapping used by :mod:`pybridge` in both directions:

==========================  ==========================================
Python                      Prolog
==========================  ==========================================
``Atom("a")`` (a ``str``)   atom ``a``
``str``                     string ``"..."``
``bytes``                   string whose code points are the bytes (0..255)
``bool``                    atom ``true`` / ``false`` (to Prolog only)
``int``                     integer (unbounded)
``float``                   float
``list``                    proper list
``tuple`` of >= 2 items     comma term ``(A, B, ...)`` (e.g. Tartarus links)
``Term(name, *args)``       compound ``name(args...)``
``Var()`` / ``Var("X")``    fresh variable; named ones are shared in one call
                            and their bindings are returned by name
==========================  ==========================================

Nothing here touches Prolog: these are plain values, built and compared in Python.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["Atom", "Term", "Var", "Blob", "atom_or_self", "robot_term"]


class Atom(str):
    """A Prolog atom. It is a ``str`` (``Atom("a") == "a"``) with its own type so that the
    converter can tell atoms from strings."""

    __slots__ = ()

    def __repr__(self) -> str:
        return f"Atom({str.__repr__(self)})"


_var_ids = itertools.count()


@dataclass(frozen=True)
class Var:
    """A Prolog variable. ``Var()`` is anonymous; ``Var("X")`` names an output binding."""

    name: str | None = None
    _id: int = field(default_factory=lambda: next(_var_ids), compare=False, repr=False)


@dataclass(frozen=True)
class Term:
    """A compound term ``name(*args)``."""

    name: str
    args: tuple[Any, ...]

    def __init__(self, name: str, *args: Any) -> None:
        if not isinstance(name, str):
            raise TypeError(f"functor name must be a str, not {type(name).__name__}")
        object.__setattr__(self, "name", str(name))
        object.__setattr__(self, "args", tuple(args))

    @property
    def arity(self) -> int:
        """Number of arguments."""
        return len(self.args)

    def __repr__(self) -> str:
        inner = ", ".join(repr(a) for a in (self.name, *self.args))
        return f"Term({inner})"


@dataclass(frozen=True)
class Blob:
    """A Prolog blob that is not text (stream, message queue, clause reference, ...),
    returned by its printed form. It cannot be sent back to Prolog."""

    text: str


def atom_or_self(value: Any) -> Any:
    """``Atom(value)`` if value is a plain ``str``, otherwise value unchanged."""
    if isinstance(value, str) and not isinstance(value, Atom):
        return Atom(value)
    return value


def robot_term(robot_id: Any) -> Any:
    """A robot id as Prolog sees it: an atom for a ``str``, an integer for an ``int``.

    Raises
    ------
    TypeError
        Neither (a ``bool`` included).
    """
    if isinstance(robot_id, bool) or not isinstance(robot_id, (str, int, np.integer)):
        raise TypeError(f"a robot id is a str or an int, not {type(robot_id).__name__}")
    return atom_or_self(robot_id) if isinstance(robot_id, str) else int(robot_id)
