"""The exception root of :mod:`dfrl.experiments`."""

from __future__ import annotations


class ExperimentError(RuntimeError):
    """The experiment could not be started or run."""
