"""The ``dfrl`` command line as a whole: its commands, and help without a command."""

from __future__ import annotations

import pytest

from dfrl.experiments.cli import build_parser, main

COMMANDS = [
    "node",
    "demo",
    "run",
    "inject",
    "join",
    "collect",
    "check-history",
    "bench",
    "train",
    "eval",
    "baselines",
    "render-arenas",
    "transfer",
    "transfer-study",
    "sweep",
    "paper",
    "speedup",
    "reference",
    "hetero",
    "robot",
    "view",
    "secret",
    "certs",
]


def test_every_command_is_listed_in_order() -> None:
    sub = next(a for a in build_parser()._actions if a.dest == "command")
    assert list(sub.choices) == COMMANDS
    bench = sub.choices["bench"]
    inner = next(a for a in bench._actions if a.dest == "benchmark")
    assert list(inner.choices)[:4] == ["migrate", "sim", "round", "bridge"]


def test_no_command_prints_help_and_exits_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main([]) == 2
    assert "render-arenas" in capsys.readouterr().out
