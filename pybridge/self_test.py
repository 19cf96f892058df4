"""The start-up self-test of the table codecs against this SWI-Prolog.

Both sides of each codec (``dfrl.pybridge.codec`` in Python, ``table_codec.pl`` in Prolog)
must agree bit for bit, in both directions, before the node uses them. fts is checked
byte for byte first: Prolog's encoder and Python's must make the same bytes, and only then
are Python-made bytes given to Prolog to decode (``fast_term_serialized/2`` aborts the
process on malformed input).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dfrl.pybridge import codec as _codec
from dfrl.pybridge.engine import Prolog
from dfrl.pybridge.errors import BridgeError, PrologFailure
from dfrl.pybridge.terms import Atom, Term, Var

__all__ = ["SelfTestReport", "self_test", "self_test_samples", "CODEC_MODULE"]

CODEC_MODULE = "table_codec"


@dataclass(frozen=True)
class SelfTestReport:
    """Outcome of the start-up codec self-test."""

    fts_ok: bool
    text_ok: bool
    detail: str


def self_test_samples() -> list[np.ndarray]:
    """Value lists whose fts headers need varints of 1, 2 and 3 bytes, and awkward floats."""
    rng = np.random.default_rng(20240611)
    special = np.array(
        [
            0.0,
            -0.0,
            1.0,
            -2.5,
            0.1,
            1 / 3,
            5e-324,
            2.2250738585072014e-308,
            1.7976931348623157e308,
            -1e-300,
            1e22,
            123456.789e-12,
        ]
    )
    return [
        np.empty(0),
        np.array([1.0]),
        special,  # varints of 1 byte
        rng.standard_normal(13) * 1e3,  # 10*13+1 = 131: 2-byte varint
        rng.uniform(-1e6, 1e6, 1700),  # 17001: 3-byte varint
    ]


def _call(prolog: Prolog, name: str, *args: object) -> dict:
    sol = prolog.call(name, *args, module=CODEC_MODULE)
    if sol is None:
        raise PrologFailure(f"{CODEC_MODULE}:{name}/{len(args)} failed")
    return sol


def prolog_encode(prolog: Prolog, codec: str, values: np.ndarray) -> bytes:
    """The bytes of ``table_codec:encode_values(Codec, Floats, Data)`` for ``values``."""
    floats = [float(x) for x in np.asarray(values, dtype=np.float64).reshape(-1)]
    data = _call(prolog, "encode_values", Atom(codec), floats, Var("D"))["D"]
    return data.args[0].encode("latin-1")


def prolog_decode(prolog: Prolog, codec: str, data: bytes | bytearray) -> np.ndarray:
    """``table_codec:decode_values(Codec(Data), Floats)`` as a float64 array (N,)."""
    values = _call(prolog, "decode_values", Term(codec, data), Var("L"))["L"]
    return np.array(values, dtype=np.float64)


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and np.array_equal(a.view(np.int64), b.view(np.int64))


def _fts_agrees(prolog: Prolog, values: np.ndarray) -> str | None:
    made = prolog_encode(prolog, "fts", values)
    if made != bytes(_codec.encode_fts(values)):
        return f"fts bytes differ for {values.size} floats"
    if not _same_bits(prolog_decode(prolog, "fts", made), values):
        return f"fts read-back differs for {values.size} floats"
    if not _same_bits(_codec.decode_fts(made), values):
        return f"fts Python decode differs for {values.size} floats"
    return None


def _text_agrees(prolog: Prolog, values: np.ndarray) -> str | None:
    if not _same_bits(_codec.decode_text(prolog_encode(prolog, "text", values)), values):
        return f"text Prolog -> Python differs for {values.size} floats"
    if not _same_bits(prolog_decode(prolog, "text", _codec.encode_text(values)), values):
        return f"text Python -> Prolog differs for {values.size} floats"
    return None


def self_test(prolog: Prolog) -> SelfTestReport:
    """Check both codecs against this SWI-Prolog (``table_codec.pl`` must be loaded).

    Raises
    ------
    BridgeError
        If even the text codec fails (the bridge cannot work at all).
    """
    fts_ok, text_ok, notes = True, True, []
    for values in self_test_samples():
        if fts_ok:
            try:
                note = _fts_agrees(prolog, values)
            except (BridgeError, UnicodeError) as exc:
                note = f"fts: {exc}"
            if note:
                fts_ok = False
                notes.append(note)
        if text_ok:
            try:
                note = _text_agrees(prolog, values)
            except (BridgeError, UnicodeError) as exc:
                note = f"text: {exc}"
            if note:
                text_ok = False
                notes.append(note)
    if not text_ok:
        raise BridgeError("the text codec failed its self-test: " + "; ".join(notes))
    return SelfTestReport(fts_ok, text_ok, "; ".join(notes) or "ok")
