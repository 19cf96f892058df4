"""Table codecs: float64 arrays <-> the compact strings that cross the bridge.

Two encodings of a flat list of N floats, both pure numpy (no Prolog here):

``fts``
    The bytes SWI-Prolog's ``fast_term_serialized/2`` produces for a list of floats
    (verified for 9.0.4 at start-up by :meth:`dfrl.pybridge.node.Bridge.self_test`)::

        114, varint(10*N + 1), varint(6*N), N x [8, 14, <float64 little-endian>], 9

    and ``[122, 9]`` for the empty list. A varint is big-endian base 128 with the high bit
    set on every byte but the last. These bytes travel as a Prolog string whose code points
    are the bytes (ISO Latin-1).
``text``
    Comma-separated shortest round-trip float text (Python ``repr`` one way, SWI-Prolog's
    float writer the other). Slower, but it cannot crash Prolog.

Both round-trip every finite float, -0.0 and subnormals bit for bit.
"""

from __future__ import annotations

import enum

import numpy as np
import numpy.typing as npt

from dfrl.pybridge.errors import CodecError

__all__ = [
    "Codec",
    "varint",
    "encode_fts",
    "decode_fts",
    "encode_text",
    "decode_text",
    "encode",
    "decode",
]

_EMPTY = bytes([122, 9])
_FLOAT_TAG = (8, 14)
#: one list element: the 2 tag bytes (8, 14) then the little-endian double, packed (10 bytes)
_ELEMENT = np.dtype([("tag", "<u2"), ("value", "<f8")])
_TAG_WORD = _FLOAT_TAG[0] | (_FLOAT_TAG[1] << 8)


class Codec(str, enum.Enum):
    """How float lists cross the bridge."""

    FTS = "fts"
    TEXT = "text"


def varint(n: int) -> bytes:
    """Big-endian base-128 varint, high bit set on all bytes but the last.

    >>> list(varint(131)), list(varint(200001))
    ([129, 3], [140, 154, 65])
    """
    if n < 0:
        raise ValueError("varint of a negative number")
    out = [n & 0x7F]
    n >>= 7
    while n:
        out.append(0x80 | (n & 0x7F))
        n >>= 7
    return bytes(reversed(out))


def _read_varint(buf: bytes | bytearray, pos: int) -> tuple[int, int]:
    value = 0
    for _ in range(10):
        if pos >= len(buf):
            raise CodecError("truncated varint")
        b = buf[pos]
        pos += 1
        value = (value << 7) | (b & 0x7F)
        if not b & 0x80:
            return value, pos
    raise CodecError("varint too long")


def encode_fts(values: npt.ArrayLike) -> bytes | bytearray:
    """Encode values (any shape, flattened row-major) as fts bytes.

    Parameters
    ----------
    values : array_like of float, shape (...)

    Returns
    -------
    bytes-like
        ``fast_term_serialized/2`` form of the list of ``values.size`` floats (a
        ``bytearray`` filled in place: one allocation, no copy).
    """
    flat = np.asarray(values, dtype="<f8").reshape(-1)
    n = flat.size
    if n == 0:
        return _EMPTY
    header = b"r" + varint(10 * n + 1) + varint(6 * n)
    buf = bytearray(len(header) + 10 * n + 1)
    buf[: len(header)] = header
    buf[-1] = 9
    body = np.frombuffer(buf, dtype=_ELEMENT, count=n, offset=len(header))
    body["tag"] = _TAG_WORD
    body["value"] = flat
    return buf


def decode_fts(data: bytes | bytearray, expected: int | None = None) -> np.ndarray:
    """Decode fts bytes into a float64 array of shape (N,).

    Parameters
    ----------
    data : bytes
        Output of ``fast_term_serialized/2`` for a list of floats.
    expected : int, optional
        Required N; a mismatch raises :class:`CodecError`.

    Raises
    ------
    CodecError
        If data is not exactly the encoding of a list of floats.
    """
    if data == _EMPTY:
        n = 0
        out = np.empty(0, dtype=np.float64)
    else:
        if len(data) < 3 or data[0] != 114 or data[-1] != 9:
            raise CodecError("not an fts float list (bad header or trailer)")
        size, pos = _read_varint(data, 1)
        cells, pos = _read_varint(data, pos)
        if (size - 1) % 10 or size < 11:
            raise CodecError(f"not an fts float list (size field {size})")
        n = (size - 1) // 10
        if cells != 6 * n or len(data) != pos + 10 * n + 1:
            raise CodecError(
                "not an fts float list (length mismatch: not all elements are floats?)"
            )
        body = np.frombuffer(data, dtype=_ELEMENT, count=n, offset=pos)
        if not np.all(body["tag"] == _TAG_WORD):
            raise CodecError("not an fts float list (an element is not a float)")
        out = body["value"].astype(np.float64)
    if expected is not None and n != expected:
        raise CodecError(f"expected {expected} values, got {n}")
    return out


def _float_text(x: float) -> str:
    if x != x:
        return "1.5NaN"
    if x == float("inf"):
        return "1.0Inf"
    if x == float("-inf"):
        return "-1.0Inf"
    return repr(x)


def encode_text(values: npt.ArrayLike) -> bytes:
    """Encode values as comma-separated float text readable by SWI-Prolog (ASCII bytes)."""
    flat = np.asarray(values, dtype=np.float64).reshape(-1)
    if flat.size and np.isfinite(flat).all():
        return ",".join(map(repr, flat.tolist())).encode("ascii")
    return ",".join(map(_float_text, flat.tolist())).encode("ascii")


def _parse_float(token: str) -> float:
    if token.endswith("Inf"):
        return float("-inf") if token.startswith("-") else float("inf")
    if token.endswith("NaN"):
        return float("nan")
    return float(token)


def decode_text(data: bytes | str, expected: int | None = None) -> np.ndarray:
    """Decode comma-separated float text (as SWI-Prolog writes it) into float64 (N,)."""
    text = data.decode("ascii") if isinstance(data, (bytes, bytearray)) else data
    tokens = text.split(",") if text else []
    try:
        try:
            out = np.array(tokens, dtype=np.float64)
        except ValueError:
            out = np.array([_parse_float(t) for t in tokens], dtype=np.float64)
    except ValueError as exc:
        raise CodecError(f"malformed float text: {exc}") from None
    if expected is not None and out.size != expected:
        raise CodecError(f"expected {expected} values, got {out.size}")
    return out


def encode(codec: Codec, values: npt.ArrayLike) -> bytes | bytearray:
    """Encode with the given codec."""
    return encode_fts(values) if codec is Codec.FTS else encode_text(values)


def decode(codec: Codec, data: bytes, expected: int | None = None) -> np.ndarray:
    """Decode with the given codec."""
    return decode_fts(data, expected) if codec is Codec.FTS else decode_text(data, expected)
