"""Fixtures of the platform tests (real swipl processes on loopback)."""

from tests.platform.conftest import procs  # noqa: F401  (a fixture, used by name)
