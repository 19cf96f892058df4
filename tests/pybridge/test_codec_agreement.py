"""Both sides of each table codec agree: ``dfrl.pybridge.codec`` (Python) and
``pybridge/table_codec.pl`` (Prolog) make the same fts bytes, and each decodes what the
other encodes, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from dfrl.pybridge import codec
from dfrl.pybridge.self_test import prolog_decode, prolog_encode


def _table(shape: tuple[int, int], seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    table = rng.standard_normal(shape) * 10.0 ** rng.integers(-300, 300, shape)
    flat = table.reshape(-1)
    awkward = [
        -1.5,
        -0.0,
        5e-324,
        -2.2250738585072014e-308,
        1.7976931348623157e308,
        np.inf,
        -np.inf,
        np.nan,
    ]
    flat[: min(flat.size, len(awkward))] = awkward[: flat.size]
    return table


def _bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64).reshape(-1).view(np.int64)


TABLES = {
    "1x1": np.array([[-3.25]]),
    "1x1-nan": np.array([[np.nan]]),
    "81x3": _table((81, 3), 1),
    "large-5000x4": _table((5000, 4), 2),
}


@pytest.mark.parametrize("name", TABLES)
def test_fts_bytes_identical(node, name: str) -> None:
    table = TABLES[name]
    python_bytes = bytes(codec.encode_fts(table))
    assert prolog_encode(node.prolog, "fts", table) == python_bytes
    assert np.array_equal(_bits(prolog_decode(node.prolog, "fts", python_bytes)), _bits(table))
    assert np.array_equal(_bits(codec.decode_fts(python_bytes, expected=table.size)), _bits(table))


@pytest.mark.parametrize("name", TABLES)
def test_text_both_ways(node, name: str) -> None:
    table = TABLES[name]
    from_prolog = codec.decode_text(prolog_encode(node.prolog, "text", table), expected=table.size)
    assert np.array_equal(_bits(from_prolog), _bits(table))
    from_python = prolog_decode(node.prolog, "text", codec.encode_text(table))
    assert np.array_equal(_bits(from_python), _bits(table))


def test_empty_list(node) -> None:
    assert prolog_encode(node.prolog, "fts", np.empty(0)) == bytes(codec.encode_fts([])) == b"z\t"
    assert prolog_decode(node.prolog, "fts", b"z\t").size == 0
    assert prolog_encode(node.prolog, "text", np.empty(0)) == codec.encode_text([]) == b""
