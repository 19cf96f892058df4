"""The table codecs alone (pure numpy, no Prolog)."""

from __future__ import annotations

import numpy as np
import pytest

from dfrl.pybridge import codec
from dfrl.pybridge.errors import CodecError


def test_varint_examples() -> None:
    assert list(codec.varint(0)) == [0]
    assert list(codec.varint(127)) == [127]
    assert list(codec.varint(131)) == [129, 3]
    assert list(codec.varint(200001)) == [140, 154, 65]


def test_fts_known_bytes() -> None:
    assert codec.encode_fts([]) == bytes([122, 9])
    one = codec.encode_fts([1.0])
    assert list(one) == [114, 11, 6, 8, 14, 0, 0, 0, 0, 0, 0, 240, 63, 9]


def _awkward(n: int, seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    bits = rng.integers(0, 2**63, n, dtype=np.int64) * rng.choice([1, -1], n)
    values = bits.view(np.float64).copy()
    values[~np.isfinite(values)] = 0.5
    values[:6] = [0.0, -0.0, 5e-324, -2.2250738585072014e-308, 1.7976931348623157e308, 0.1]
    return values


@pytest.mark.parametrize("n", [0, 1, 13, 1700, 20000])
def test_fts_round_trip_bit_exact(n: int) -> None:
    values = _awkward(n) if n >= 6 else np.arange(n, dtype=np.float64) / 3
    back = codec.decode_fts(codec.encode_fts(values), expected=n)
    assert back.dtype == np.float64
    assert np.array_equal(back.view(np.int64), values.view(np.int64))


@pytest.mark.parametrize("n", [0, 1, 13, 2000])
def test_text_round_trip_bit_exact(n: int) -> None:
    values = _awkward(n) if n >= 6 else np.arange(n, dtype=np.float64) / 3
    back = codec.decode_text(codec.encode_text(values), expected=n)
    assert np.array_equal(back.view(np.int64), values.view(np.int64))


def test_text_non_finite_in_prolog_syntax() -> None:
    data = codec.encode_text([np.inf, -np.inf, np.nan, 1.0])
    assert data == b"1.0Inf,-1.0Inf,1.5NaN,1.0"
    back = codec.decode_text(data)
    assert back[0] == np.inf and back[1] == -np.inf and np.isnan(back[2]) and back[3] == 1.0


@pytest.mark.parametrize(
    "data",
    [
        b"",
        b"r",
        bytes([114, 11, 6, 8, 14, 0, 0, 0, 0, 0, 0, 240, 63]),  # no trailer
        bytes([114, 11, 6, 8, 15, 0, 0, 0, 0, 0, 0, 240, 63, 9]),  # wrong tag
        bytes([114, 21, 12, 8, 14, 0, 0, 0, 0, 0, 0, 240, 63, 9]),  # says 2, has 1
        bytes([114, 11, 6, 8, 14, 0, 0, 0, 0, 0, 0, 240, 63, 0, 9]),  # extra byte
        bytes([115, 11, 6, 8, 14, 0, 0, 0, 0, 0, 0, 240, 63, 9]),  # wrong header
    ],
)
def test_fts_rejects_malformed(data: bytes) -> None:
    with pytest.raises(CodecError):
        codec.decode_fts(data)


def test_expected_count_enforced() -> None:
    with pytest.raises(CodecError):
        codec.decode_fts(codec.encode_fts([1.0, 2.0]), expected=3)
    with pytest.raises(CodecError):
        codec.decode_text(b"1.0,2.0", expected=3)
    with pytest.raises(CodecError):
        codec.decode_text(b"1.0,abc")
