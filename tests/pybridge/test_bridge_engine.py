"""The Python <-> Prolog term converter and calls with bound arguments (real SWI-Prolog)."""

from __future__ import annotations

import numpy as np
import pytest

from dfrl.pybridge import Atom, NodeStateError, PrologError, Term, TermConversionError, Var
from dfrl.pybridge.engine import prolog


@pytest.fixture(scope="module")
def pl():
    return prolog()


@pytest.mark.parametrize(
    "value",
    [
        Atom("plain"),
        Atom("with space"),
        Atom("quote'and\"dq"),
        Atom("héllo ∀"),
        Atom(""),
        Atom("foo), halt, (bar"),
        Atom("[]"),
        "a string",
        "",
        "nul\x00inside",
        "ünï ∀",
        0,
        -1,
        2**62,
        -(2**63),
        2**63,
        -(2**100),
        10**40,
        0.0,
        -0.0,
        1.5,
        5e-324,
        1.7976931348623157e308,
        float("inf"),
        [],
        [1, 2, 3],
        [Atom("a"), "b", [1.5, []]],
        (Atom("localhost"), 5000),
        (1, 2, 3),
        Term("f", Atom("a")),
        Term("g", Term("h", 1, [2]), "s"),
        Term("-", Atom("x"), 1),
    ],
)
def test_round_trip_through_prolog(pl, value) -> None:
    sol = pl.call("=", Var("X"), value)
    assert sol is not None
    back = sol["X"]
    assert back == value and type(back) is type(value)
    if isinstance(value, float):
        assert np.float64(back).view(np.int64) == np.float64(value).view(np.int64)


def test_bytes_become_latin1_string_with_nul(pl) -> None:
    data = bytes(range(256)) * 3
    sol = pl.call("string_length", data, Var("N"))
    assert sol == {"N": 768}
    sol = pl.call("string_code", 1, data, Var("C"))
    assert sol == {"C": 0}
    sol = pl.call("=", Var("S"), data)
    assert sol["S"].encode("latin-1") == data


def test_atoms_are_not_parsed(pl) -> None:
    # a value that would be code if pasted into a goal string stays one atom
    sol = pl.call("atom_length", Atom("x), halt(1"), Var("N"))
    assert sol == {"N": 10}
    assert pl.call("atom", Atom("X")) == {}  # an atom, not a variable
    assert pl.call("atom", "X") is None  # str is a string


def test_named_variables_are_shared(pl) -> None:
    x = Var("X")
    sol = pl.call("=", Term("f", x, x), Term("f", 1, Var("Y")))
    assert sol == {"X": 1, "Y": 1}
    anon = Var()
    sol = pl.call("=", Term("f", anon, anon), Term("f", 1, Var("Z")))
    assert sol == {"Z": 1}


def test_bool_and_numpy_scalars(pl) -> None:
    assert pl.call("=", Var("X"), True) == {"X": Atom("true")}
    assert pl.call("=", Var("X"), np.int64(7)) == {"X": 7}
    assert pl.call("=", Var("X"), np.float32(0.5)) == {"X": 0.5}


def test_unconvertible_values(pl) -> None:
    with pytest.raises(TermConversionError):
        pl.call("=", Var("X"), {"a": 1})
    with pytest.raises(TermConversionError):
        pl.call("=", Var("X"), (1,))
    with pytest.raises(TermConversionError):
        pl.call("=", Var("X"), None)


def test_failure_and_all_solutions(pl) -> None:
    assert pl.call("fail") is None
    assert pl.call_all("between", 1, 3, Var("X")) == [{"X": 1}, {"X": 2}, {"X": 3}]
    assert pl.call_all("between", 1, 3, Var("X"), limit=2) == [{"X": 1}, {"X": 2}]


def test_prolog_error_keeps_formal_term(pl) -> None:
    with pytest.raises(PrologError) as info:
        pl.call("atom_length", 42.5, Atom("not_a_number"))
    err = info.value
    assert isinstance(err.term, Term) and err.term.name == "error"
    assert err.formal == Term("type_error", Atom("integer"), Atom("not_a_number"))
    with pytest.raises(PrologError) as info:
        pl.call("throw", Term("my_ball", [1, "two"]))
    assert info.value.term == Term("my_ball", [1, "two"])


def test_unknown_predicate_is_existence_error(pl) -> None:
    with pytest.raises(PrologError) as info:
        pl.call("no_such_predicate_xyz", 1)
    assert info.value.formal.name == "existence_error"


def test_open_pyswip_query_is_respected(pl) -> None:
    from pyswip import Prolog as PyswipProlog

    gen = PyswipProlog.query("between(1, 3, X)")
    next(gen)
    try:
        with pytest.raises(NodeStateError):
            pl.call("true")
    finally:
        gen.close()
    assert pl.call("true") == {}


def test_partial_list_and_blob(pl) -> None:
    sol = pl.call("=", Var("X"), Term("[|]", 1, Var("T")))
    assert isinstance(sol["X"], Term) and sol["X"].name == "[|]"
    sol = pl.call("message_queue_create", Var("Q"))
    from dfrl.pybridge import Blob

    assert isinstance(sol["Q"], Blob)


def test_bytearray_and_memoryview_strings(pl) -> None:
    data = bytearray(b"\x00a\xff\x00")
    assert pl.call("string_length", data, Var("N")) == {"N": 4}
    assert pl.call("=", Var("S"), memoryview(b"\x00\x01"))["S"] == "\x00\x01"
    assert pl.call("=", Var("S"), bytearray())["S"] == ""


def test_dicts_and_reserved_functors_come_back_as_blobs(pl) -> None:
    from dfrl.pybridge import Blob

    sol = pl.call("dict_create", Var("D"), Atom("t"), [Term("-", Atom("a"), 1)])
    assert sol["D"] == Blob("t{a:1}")


def test_cyclic_binding_is_a_conversion_error(pl) -> None:
    x = Var("X")
    with pytest.raises(TermConversionError):
        pl.call("=", x, Term("f", x))
    assert pl.call("true") == {}  # the query was closed


def test_deep_term_is_a_conversion_error(pl) -> None:
    step = Term(">>", [Var(), Var("A0"), Var("A")], Term("=", Var("A"), Term("f", Var("A0"))))
    with pytest.raises(TermConversionError):
        pl.call("foldl", step, list(range(5000)), Atom("x"), Var("T"))  # f(f(...f(x)...))
    sol = pl.call("foldl", step, list(range(50)), Atom("x"), Var("T"))
    assert sol["T"].name == "f"
