"""The SWI-Prolog agent platform, shipped as Prolog source files.

The platform itself is pure Prolog; this package only locates its files so that Python
code (the bridge, the node launcher, benchmarks) can load them.
"""

from __future__ import annotations

from pathlib import Path

PLATFORM_DIR: Path = Path(__file__).resolve().parent
"""Folder holding the platform's ``.pl`` files."""

ENTRY_POINT: Path = PLATFORM_DIR / "tartarus.pl"
"""The file that loads the whole platform with its Tartarus-style API."""

DFRL_AGENT_DIR: Path = PLATFORM_DIR / "dfrl_agent"
"""Folder of the dFRL itinerary agent (its modules, console, launch and control scripts, and
example aggregation methods); ``agents.pl`` beside it is the agent runtime."""
