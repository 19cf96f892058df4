"""Calling SWI-Prolog from Python with bound arguments, on top of pyswip's libswipl.

pyswip initialises the embedded Prolog when imported; this module then talks to the same
``libswipl`` through its own ctypes prototypes (pyswip's string-built goals, its
NUL-truncating string getters and its process-wide open-query flag are avoided or
respected). Goals are never built from text: every argument is converted from a Python
value (see :mod:`dfrl.pybridge.terms`) into a term with the foreign language interface, the
predicate is called through ``PL_open_query`` and the query is always closed.

One process-wide lock serialises calls. A Prolog exception arrives as
:class:`~dfrl.pybridge.errors.PrologError` whose ``term`` is the exception term as data.
"""

from __future__ import annotations

import ctypes
import threading
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from ctypes import POINTER, byref, c_char_p, c_double, c_int, c_int64, c_size_t, c_uint, c_void_p
from fractions import Fraction
from typing import Any

import numpy as np

from dfrl.pybridge.errors import BridgeError, NodeStateError, PrologError, TermConversionError
from dfrl.pybridge.terms import Atom, Blob, Term, Var

__all__ = ["Prolog", "prolog"]

# --- constants of SWI-Prolog.h (9.x) -----------------------------------------------------
PL_VARIABLE, PL_ATOM, PL_INTEGER, PL_RATIONAL, PL_FLOAT, PL_STRING, PL_TERM = 1, 2, 3, 4, 5, 6, 7
PL_NIL, PL_BLOB, PL_LIST_PAIR, PL_DICT = 8, 9, 10, 44
PL_Q_NODEBUG, PL_Q_CATCH_EXCEPTION = 0x04, 0x08
CVT_ATOM, CVT_STRING, CVT_INTEGER, CVT_RATIONAL, CVT_WRITEQ = 0x01, 0x02, 0x08, 0x10, 0x200
BUF_STACK, BUF_ALLOW_STACK = 0x10000, 0x40000
REP_ISO_LATIN_1, REP_UTF8 = 0x0, 0x100000

term_t = c_size_t
atom_t = c_size_t
functor_t = c_size_t
qid_t = c_size_t
fid_t = c_size_t
buf_mark_t = c_size_t


class _Lib:
    """ctypes prototypes of the libswipl functions we use (fresh function pointers, so
    pyswip's own prototypes are left as they are)."""

    def __init__(self) -> None:
        import pyswip  # noqa: F401  (initialises Prolog)
        from pyswip import core

        lib = core._lib

        def fn(name: str, restype: Any, *argtypes: Any) -> Any:
            f = lib[name]
            f.restype = restype
            f.argtypes = list(argtypes)
            return f

        self.new_term_ref = fn("PL_new_term_ref", term_t)
        self.new_term_refs = fn("PL_new_term_refs", term_t, c_int)
        self.put_variable = fn("PL_put_variable", c_int, term_t)
        self.put_term = fn("PL_put_term", c_int, term_t, term_t)
        self.put_chars = fn("PL_put_chars", c_int, term_t, c_int, c_size_t, c_void_p)
        self.put_int64 = fn("PL_put_int64", c_int, term_t, c_int64)
        self.put_float = fn("PL_put_float", c_int, term_t, c_double)
        self.put_nil = fn("PL_put_nil", c_int, term_t)
        self.cons_list = fn("PL_cons_list", c_int, term_t, term_t, term_t)
        self.cons_functor_v = fn("PL_cons_functor_v", c_int, term_t, functor_t, term_t)
        self.put_term_from_chars = fn(
            "PL_put_term_from_chars", c_int, term_t, c_int, c_size_t, c_char_p
        )
        self.new_atom_mbchars = fn("PL_new_atom_mbchars", atom_t, c_int, c_size_t, c_char_p)
        self.unregister_atom = fn("PL_unregister_atom", None, atom_t)
        self.new_functor_sz = fn("PL_new_functor_sz", functor_t, atom_t, c_size_t)
        self.term_type = fn("PL_term_type", c_int, term_t)
        self.is_acyclic = fn("PL_is_acyclic", c_int, term_t)
        self.get_nchars = fn(
            "PL_get_nchars", c_int, term_t, POINTER(c_size_t), POINTER(c_void_p), c_uint
        )
        self.get_int64 = fn("PL_get_int64", c_int, term_t, POINTER(c_int64))
        self.get_float = fn("PL_get_float", c_int, term_t, POINTER(c_double))
        self.get_name_arity_sz = fn(
            "PL_get_name_arity_sz", c_int, term_t, POINTER(atom_t), POINTER(c_size_t)
        )
        self.get_arg_sz = fn("PL_get_arg_sz", c_int, c_size_t, term_t, term_t)
        self.atom_mbchars = fn(
            "PL_atom_mbchars", c_int, atom_t, POINTER(c_size_t), POINTER(c_void_p), c_uint
        )
        self.get_list = fn("PL_get_list", c_int, term_t, term_t, term_t)
        self.get_nil = fn("PL_get_nil", c_int, term_t)
        self.predicate = fn("PL_predicate", c_void_p, c_char_p, c_int, c_char_p)
        self.open_query = fn("PL_open_query", qid_t, c_void_p, c_int, c_void_p, term_t)
        self.next_solution = fn("PL_next_solution", c_int, qid_t)
        self.close_query = fn("PL_close_query", c_int, qid_t)
        self.exception = fn("PL_exception", term_t, qid_t)
        self.open_foreign_frame = fn("PL_open_foreign_frame", fid_t)
        self.discard_foreign_frame = fn("PL_discard_foreign_frame", None, fid_t)
        self.mark_string_buffers = fn("PL_mark_string_buffers", None, POINTER(buf_mark_t))
        self.release_string_buffers_from_mark = fn(
            "PL_release_string_buffers_from_mark", None, buf_mark_t
        )
        self.thread_self = fn("PL_thread_self", c_int)
        self.thread_attach_engine = fn("PL_thread_attach_engine", c_int, c_void_p)


class Prolog:
    """Deterministic calls into the embedded SWI-Prolog with bound arguments.

    Use the module-level instance :data:`prolog`. All methods are thread-safe (one lock);
    a Python thread that is not yet a Prolog thread gets an engine attached.
    """

    def __init__(self) -> None:
        self._lib = _Lib()
        self._lock = threading.RLock()
        self._predicates: dict[tuple[str, int, str | None], int] = {}
        self._functors: dict[tuple[str, int], int] = {}
        from pyswip.prolog import Prolog as _PyswipProlog

        self._pyswip = _PyswipProlog

    # -- public API --------------------------------------------------------------------------
    def call(self, name: str, *args: Any, module: str | None = None) -> dict[str, Any] | None:
        """Call ``module:name(args...)`` once.

        Returns
        -------
        dict or None
            Bindings of the named :class:`~dfrl.pybridge.terms.Var` arguments on success,
            ``None`` if the goal failed.

        Raises
        ------
        PrologError
            If the goal raised an exception; ``.term`` holds the exception term.
        TermConversionError
            If an argument has no Prolog form.
        """
        sols = self._run(name, args, module, 1)
        return sols[0] if sols else None

    def call_all(
        self, name: str, *args: Any, module: str | None = None, limit: int | None = None
    ) -> list[dict[str, Any]]:
        """All solutions (at most ``limit``) of ``module:name(args...)`` as binding dicts."""
        return self._run(name, args, module, limit)

    def once(self, goal: Term | Atom, module: str | None = None) -> dict[str, Any] | None:
        """Call a goal given as a :class:`Term` (or an :class:`Atom` for arity 0)."""
        if isinstance(goal, Term):
            return self.call(goal.name, *goal.args, module=module)
        if isinstance(goal, Atom):
            return self.call(str(goal), module=module)
        raise TermConversionError(f"a goal must be a Term or an Atom, not {type(goal).__name__}")

    # -- internals ----------------------------------------------------------------------------
    def _ensure_engine(self) -> None:
        if self._lib.thread_self() == -1 and self._lib.thread_attach_engine(None) < 0:
            raise BridgeError("cannot attach a Prolog engine to this thread")

    def _predicate(self, name: str, arity: int, module: str | None) -> int:
        key = (name, arity, module)
        pred = self._predicates.get(key)
        if pred is None:
            pred = self._lib.predicate(
                name.encode("utf-8"), arity, module.encode("utf-8") if module else None
            )
            self._predicates[key] = pred
        return pred

    def _functor(self, name: str, arity: int) -> int:
        key = (name, arity)
        f = self._functors.get(key)
        if f is None:
            raw = name.encode("utf-8")
            a = self._lib.new_atom_mbchars(REP_UTF8, len(raw), raw)
            f = self._lib.new_functor_sz(a, arity)  # functors are permanent and keep the atom
            self._lib.unregister_atom(a)
            self._functors[key] = f
        return f

    @contextmanager
    def _query_slot(self) -> Iterator[None]:
        with self._lock:
            if self._pyswip._queryIsOpen:
                raise NodeStateError("a pyswip query is still open (exhaust or close it first)")
            self._pyswip._queryIsOpen = True
            try:
                yield
            finally:
                self._pyswip._queryIsOpen = False

    def _run(
        self, name: str, args: Sequence[Any], module: str | None, limit: int | None
    ) -> list[dict[str, Any]]:
        lib = self._lib
        with self._query_slot():
            self._ensure_engine()
            fid = lib.open_foreign_frame()
            try:
                argv = lib.new_term_refs(len(args)) if args else lib.new_term_ref()
                names: dict[str, int] = {}
                for i, value in enumerate(args):
                    self._put(argv + i, value, names)
                pred = self._predicate(name, len(args), module)
                qid = lib.open_query(None, PL_Q_NODEBUG | PL_Q_CATCH_EXCEPTION, pred, argv)
                solutions: list[dict[str, Any]] = []
                try:
                    while limit is None or len(solutions) < limit:
                        if not lib.next_solution(qid):
                            ex = lib.exception(qid)
                            if ex:
                                where = f"{module}:{name}" if module else name
                                raise PrologError(self._get_top(ex), goal=f"{where}/{len(args)}")
                            break
                        solutions.append({k: self._get_top(t) for k, t in names.items()})
                finally:
                    lib.close_query(qid)
                return solutions
            finally:
                lib.discard_foreign_frame(fid)

    # -- Python -> Prolog ---------------------------------------------------------------------
    def _put(
        self, t: int, value: Any, names: dict[str, int], vars_: dict[int, int] | None = None
    ) -> None:
        lib = self._lib
        if vars_ is None:
            vars_ = {}
        if isinstance(value, Atom):
            raw = value.encode("utf-8")
            ok = lib.put_chars(t, PL_ATOM | REP_UTF8, len(raw), raw)
        elif isinstance(value, str):
            raw = value.encode("utf-8")
            ok = lib.put_chars(t, PL_STRING | REP_UTF8, len(raw), raw)
        elif isinstance(value, bytes):
            ok = lib.put_chars(t, PL_STRING | REP_ISO_LATIN_1, len(value), value)
        elif isinstance(value, (bytearray, memoryview)):
            buf = value if isinstance(value, bytearray) else bytearray(value)
            view = (ctypes.c_char * len(buf)).from_buffer(buf) if buf else b""
            ok = lib.put_chars(t, PL_STRING | REP_ISO_LATIN_1, len(buf), view)
        elif isinstance(value, (bool, np.bool_)):
            raw = b"true" if value else b"false"
            ok = lib.put_chars(t, PL_ATOM | REP_UTF8, len(raw), raw)
        elif isinstance(value, (int, np.integer)):
            v = int(value)
            if -(2**63) <= v < 2**63:
                ok = lib.put_int64(t, v)
            else:
                raw = str(v).encode("ascii")  # digits only: not a goal, a number literal
                ok = lib.put_term_from_chars(t, REP_UTF8, len(raw), raw)
        elif isinstance(value, (float, np.floating)):
            ok = lib.put_float(t, float(value))
        elif isinstance(value, Var):
            if value.name is not None and value.name in names:
                ok = lib.put_term(t, names[value.name])
            elif value._id in vars_:
                ok = lib.put_term(t, vars_[value._id])
            else:
                ok = lib.put_variable(t)
                keep = lib.new_term_ref()
                lib.put_term(keep, t)
                vars_[value._id] = keep
                if value.name is not None:
                    names[value.name] = keep
        elif isinstance(value, list):
            ok = self._put_list(t, value, names, vars_)
        elif isinstance(value, tuple):
            if len(value) < 2:
                raise TermConversionError(
                    "only tuples of 2 or more items map to Prolog (comma terms)"
                )
            rest = value[1] if len(value) == 2 else value[1:]
            self._put(t, Term(",", value[0], rest), names, vars_)
            ok = None
        elif isinstance(value, Term):
            n = len(value.args)
            argv = lib.new_term_refs(n) if n else lib.new_term_ref()
            for i, a in enumerate(value.args):
                self._put(argv + i, a, names, vars_)
            ok = lib.cons_functor_v(t, self._functor(value.name, n), argv)
        else:
            raise TermConversionError(
                f"no Prolog term for a Python {type(value).__name__}: {value!r}"
            )
        if ok is not None and not ok:
            raise BridgeError(
                f"Prolog could not build a term for {type(value).__name__} (out of stack?)"
            )

    def _put_list(
        self, t: int, items: list[Any], names: dict[str, int], vars_: dict[int, int]
    ) -> int:
        lib = self._lib
        lib.put_nil(t)
        head = lib.new_term_ref()
        for item in reversed(items):
            self._put(head, item, names, vars_)
            if not lib.cons_list(t, head, t):
                return 0
        return 1

    # -- Prolog -> Python ---------------------------------------------------------------------
    def _text(self, t: int, flags: int) -> str | None:
        """Text of t. Latin-1 first (no conversion; strings carrying fts bytes are Latin-1,
        and a pointer into the stack is fine as we copy at once), UTF-8 otherwise."""
        lib = self._lib
        n = c_size_t()
        s = c_void_p()
        mark = buf_mark_t()
        lib.mark_string_buffers(byref(mark))
        try:
            if lib.get_nchars(t, byref(n), byref(s), flags | BUF_ALLOW_STACK | REP_ISO_LATIN_1):
                return ctypes.string_at(s, n.value).decode("latin-1")
            if not lib.get_nchars(t, byref(n), byref(s), flags | BUF_STACK | REP_UTF8):
                return None
            return ctypes.string_at(s, n.value).decode("utf-8")
        finally:
            lib.release_string_buffers_from_mark(mark)

    def _atom_text(self, a: int) -> str | None:
        n = c_size_t()
        s = c_void_p()
        if not self._lib.atom_mbchars(a, byref(n), byref(s), REP_UTF8):
            return None  # a reserved symbol (e.g. the functor of a dict)
        return ctypes.string_at(s, n.value).decode("utf-8")

    def _get_top(self, t: int) -> Any:
        """:meth:`_get` for a whole binding: refuses cyclic terms and too deep nesting."""
        if not self._lib.is_acyclic(t):
            raise TermConversionError("a cyclic term has no Python form")
        try:
            return self._get(t)
        except (RecursionError, ctypes.ArgumentError) as exc:
            if isinstance(exc, ctypes.ArgumentError) and "RecursionError" not in str(exc):
                raise
            raise TermConversionError("a term nested too deeply to convert") from None

    def _get(self, t: int) -> Any:
        lib = self._lib
        kind = lib.term_type(t)
        if kind == PL_VARIABLE:
            return Var()
        if kind == PL_ATOM:
            return Atom(self._text(t, CVT_ATOM))
        if kind == PL_NIL:
            return []
        if kind == PL_STRING:
            return self._text(t, CVT_STRING)
        if kind == PL_INTEGER:
            v = c_int64()
            if lib.get_int64(t, byref(v)):
                return v.value
            return int(self._text(t, CVT_INTEGER) or "0")  # beyond int64: via its digits
        if kind == PL_FLOAT:
            d = c_double()
            lib.get_float(t, byref(d))
            return d.value
        if kind == PL_RATIONAL:
            num, _, den = (self._text(t, CVT_RATIONAL) or "0").partition("r")
            return Fraction(int(num), int(den or 1))
        if kind == PL_BLOB:
            return Blob(self._text(t, CVT_WRITEQ) or "<blob>")
        if kind == PL_LIST_PAIR:
            items: list[Any] = []
            cur = lib.new_term_ref()
            lib.put_term(cur, t)
            head = lib.new_term_ref()
            while lib.get_list(cur, head, cur):
                items.append(self._get(head))
            if lib.get_nil(cur):
                return items
            tail = self._get(cur)  # partial list: [a, b | Tail]
            for item in reversed(items):
                tail = Term("[|]", item, tail)
            return tail
        if kind == PL_DICT:
            return Blob(self._text(t, CVT_WRITEQ) or "<dict>")
        name = atom_t()
        arity = c_size_t()
        fname = None
        if lib.get_name_arity_sz(t, byref(name), byref(arity)):
            fname = self._atom_text(name.value)
        if fname is None:
            return Blob(self._text(t, CVT_WRITEQ) or "<term>")
        a = lib.new_term_ref()
        args = []
        for i in range(1, arity.value + 1):
            lib.get_arg_sz(i, t, a)
            args.append(self._get(a))
        if fname == "," and len(args) == 2:
            rest = args[1]
            return (args[0], *rest) if isinstance(rest, tuple) else (args[0], rest)
        return Term(fname, *args)


_instance: Prolog | None = None
_instance_lock = threading.Lock()


def prolog() -> Prolog:
    """The process-wide :class:`Prolog` (created, and Prolog initialised, on first use)."""
    global _instance
    with _instance_lock:
        if _instance is None:
            _instance = Prolog()
        return _instance
