"""Every ``dfrl ...`` command line the READMEs show parses with today's ``dfrl`` parser: the
commands, subcommands and options they name exist and take the values shown (issue 20: "the
README's commands all run as written"; the multi-host, TLS and cluster sections are also run
word for word by their own tests).

A shown line is read as a user would type it: the comment after ``#`` dropped, optional parts
``[...]`` left out, the first of ``a|b`` alternatives taken, a number for the placeholders
``N``, ``K``, ``S``, ``W`` and ``C``. The control: a line with an option
that does not exist is refused by the same check.
"""

from __future__ import annotations

import contextlib
import io
import re
import shlex

import pytest

from dfrl.experiments.cli import build_parser
from dfrl.experiments.tools.netns import REPO_ROOT

READMES = sorted(
    {
        REPO_ROOT / "README.md",
        *REPO_ROOT.glob("*/README.md"),
        *REPO_ROOT.glob("experiments/*/README.md"),
    }
)
LINE = re.compile(r"^\s*(?:\$ )?(dfrl [a-z].*)$")
#: Placeholders the READMEs use for numbers, and what the check types for them.
COUNTS = {"N", "K", "S", "W", "C"}
NUMBER = "3"


def shown_commands() -> list[tuple[str, str]]:
    """(where, line) of every ``dfrl`` command line at the start of a README line."""
    found = []
    for readme in READMES:
        for n, text in enumerate(readme.read_text(encoding="utf-8").splitlines(), 1):
            m = LINE.match(text)
            if m:
                found.append((f"{readme.relative_to(REPO_ROOT)}:{n}", m.group(1)))
    return found


def as_typed(line: str) -> list[str]:
    """The argv a user types for a shown line (see the module doc)."""
    line = re.sub(r"\s#.*$", "", line)
    while re.search(r"\[[^\[\]]*\]", line):
        line = re.sub(r"\s*\[[^\[\]]*\]", "", line)
    words = [w.split("|")[0] if "|" in w else w for w in shlex.split(line)[1:]]
    return [NUMBER if w in COUNTS else w for w in words]


def refused(argv: list[str]) -> str | None:
    """None if ``dfrl`` parses ``argv``, else what it said."""
    said = io.StringIO()
    try:
        with contextlib.redirect_stderr(said):
            build_parser().parse_args(argv)
    except SystemExit:
        return said.getvalue().strip().splitlines()[-1] if said.getvalue().strip() else "exit"
    return None


COMMANDS = shown_commands()


def test_the_readmes_show_commands() -> None:
    assert len(COMMANDS) >= 30, COMMANDS


@pytest.mark.parametrize("where,line", COMMANDS, ids=[w for w, _ in COMMANDS])
def test_a_shown_command_parses(where: str, line: str) -> None:
    argv = as_typed(line)
    assert refused(argv) is None, f"{where}: {line!r} -> {argv}: {refused(argv)}"


def test_control_a_made_up_option_is_refused() -> None:
    assert refused(as_typed("dfrl run lan.json --no-such-option 3")) is not None
    assert refused(as_typed("dfrl bench round --entries many")) is not None
    assert refused(as_typed("dfrl bench round --entries 20000 [--rounds 30] --json")) is None
