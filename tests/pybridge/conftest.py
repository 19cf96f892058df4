"""Fixtures for the bridge tests: one embedded SWI-Prolog per pytest process (pyswip can
be initialised only once), a fresh Bridge per test."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import pytest
from bridge_helpers import HELPER, _atom


@pytest.fixture
def node() -> Iterator[Any]:
    from dfrl.pybridge import Bridge

    n = Bridge(request_timeout=5.0)
    n.call("use_module", _atom(str(HELPER)))
    try:
        yield n
    finally:
        n.close()
