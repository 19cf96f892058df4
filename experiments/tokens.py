"""How platform tokens reach the processes of a run without being seen: never on a command
line (``ps`` shows every process's argv to every user), never in a results file other than
the one secret file.

Three ways in, one text format:

``DFRL_TOKEN`` (:data:`TOKEN_ENV`)
    An environment variable holding the tokens, one per line. A parent sets it for one child
    (``subprocess.Popen(env=...)``); the child reads it once and deletes it from its own
    environment (:func:`pop_env_tokens`; the Prolog programs do the same with ``unsetenv/1``),
    so that its own children do not inherit it. A process's environment is readable by its
    owner only (``/proc/PID/environ`` is mode 0400).
``--token-file PATH``
    A file holding the tokens in the same format, readable by its owner only (mode 0600 or
    stricter: :func:`read_token_file` refuses a file other users may read or write).
``secret.token`` (:data:`SECRET_FILE`)
    The one file of a results folder that holds the run's token (mode 0600, written by
    :func:`write_secret_file`): what ``dfrl join`` and ``dfrl inject`` read to talk to the
    run (:func:`run_tokens`). ``nodes.json``, ``config.json``, ``launch_*.json``,
    ``nodes/*.json``, the logs and ``summary.md`` never hold a token.

The format: one token per line; surrounding white space and blank lines are ignored; a line of
ASCII digits only is an integer token (as Tartarus tokens are), any other line an atom. So a
token is an integer >= 0 or a text without white space (:func:`token_problem`).
"""

from __future__ import annotations

import os
import re
import secrets
import stat
from collections.abc import Iterable, Mapping
from pathlib import Path

__all__ = [
    "SECRET_FILE",
    "TOKEN_ENV",
    "Token",
    "TokenError",
    "env_with_tokens",
    "format_tokens",
    "new_secret",
    "parse_tokens",
    "pop_env_tokens",
    "read_token_file",
    "run_tokens",
    "token_problem",
    "write_secret_file",
]

Token = int | str
"""A platform token: an integer >= 0 or an atom's text (no white space)."""

TOKEN_ENV = "DFRL_TOKEN"
"""The environment variable a parent hands its child's tokens in (one per line)."""

SECRET_FILE = "secret.token"
"""The file of a results folder that holds the run's token (mode 0600)."""

_DIGITS = re.compile(r"[0-9]+\Z")
_NO_SPACE = re.compile(r"\S+\Z")
MAX_TOKEN_CHARS = 1024


SECRET_PREFIX = "dfrl_"


def new_secret() -> str:
    """A token of 256 random bits: ``dfrl_`` and 64 hex digits (an atom Prolog writes unquoted,
    so its canonical text, the key of the token proof, is the token itself).

    The prefix keeps it from being read as a number (digit-only tokens are integers, as
    Tartarus tokens are).
    """
    return SECRET_PREFIX + secrets.token_hex(32)


class TokenError(ValueError):
    """Tokens that cannot be read: an unsafe or unreadable file, a malformed token."""


def token_problem(value: object) -> str | None:
    """Why ``value`` cannot be a token (None: it can): an integer >= 0, or a non-empty text of
    at most 1024 characters without white space (a line of the token format)."""
    if isinstance(value, bool) or not isinstance(value, (int, str)):
        return f"expected an integer or a string, got {value!r}"
    if isinstance(value, int):
        return None if value >= 0 else f"must be >= 0, got {value!r}"
    if not value:
        return "must not be empty"
    if not _NO_SPACE.match(value):
        return "must not contain white space"
    if len(value) > MAX_TOKEN_CHARS:
        return f"longer than {MAX_TOKEN_CHARS} characters"
    return None


def parse_tokens(text: str) -> list[Token]:
    """Tokens of ``text`` in the token format (digits: an integer).

    >>> parse_tokens("1111\\n dfrl_ab \\n\\n")
    [1111, 'dfrl_ab']
    """
    out: list[Token] = []
    for line in text.splitlines():
        line = line.strip()
        if line:
            out.append(int(line) if _DIGITS.match(line) else line)
    return out


def format_tokens(tokens: Iterable[Token]) -> str:
    """The token format of ``tokens`` (one per line, a trailing newline).

    Raises
    ------
    TokenError
        A value is not a token (:func:`token_problem`).
    """
    lines = []
    for t in tokens:
        why = token_problem(t)
        if why is not None:
            raise TokenError(f"not a token: {why}")
        lines.append(str(t))
    return "".join(line + "\n" for line in lines)


def env_with_tokens(
    tokens: Iterable[Token], base: Mapping[str, str] | None = None
) -> dict[str, str]:
    """The environment of a child that gets ``tokens``: ``base`` (default this process's
    environment) with :data:`TOKEN_ENV` set (or removed when there are no tokens)."""
    env = dict(os.environ if base is None else base)
    text = format_tokens(tokens)
    if text:
        env[TOKEN_ENV] = text
    else:
        env.pop(TOKEN_ENV, None)
    return env


def pop_env_tokens() -> list[Token]:
    """The tokens in :data:`TOKEN_ENV` (none: ``[]``), deleted from this process's environment
    so that its children do not inherit them."""
    return parse_tokens(os.environ.pop(TOKEN_ENV, ""))


def read_token_file(path: str | os.PathLike[str]) -> list[Token]:
    """The tokens in ``path`` (the token format).

    Raises
    ------
    TokenError
        The file cannot be read, other users may read or write it (``chmod 600 PATH``), or
        it holds no token.
    """
    p = Path(path)
    try:
        with open(p, "rb") as fh:
            mode = os.fstat(fh.fileno()).st_mode
            data = fh.read(64 * 1024)
    except OSError as exc:
        raise TokenError(f"token file {p}: {exc.strerror}") from None
    if mode & (stat.S_IRWXG | stat.S_IRWXO):
        raise TokenError(
            f"token file {p}: other users may read it (mode "
            f"{stat.S_IMODE(mode):04o}); run chmod 600 {p}"
        )
    try:
        tokens = parse_tokens(data.decode("utf-8"))
    except UnicodeDecodeError:
        raise TokenError(f"token file {p}: not UTF-8 text") from None
    if not tokens:
        raise TokenError(f"token file {p}: holds no token")
    return tokens


def write_secret_file(path: str | os.PathLike[str], tokens: Iterable[Token]) -> Path:
    """Write ``tokens`` to a new file ``path`` of mode 0600 (created so: never readable by
    others, not even for a moment; an existing file or link there is replaced, not followed).

    Raises
    ------
    TokenError
        A value is not a token.
    """
    p = Path(path)
    text = format_tokens(tokens)
    tmp = p.with_name(f".{p.name}.{os.getpid()}.tmp")
    try:
        tmp.unlink()
    except FileNotFoundError:
        pass
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as fh:
        fh.write(text)
    os.replace(tmp, p)
    return p


def run_tokens(results_dir: str | os.PathLike[str]) -> list[Token]:
    """The tokens of the run whose results folder is ``results_dir`` (its
    :data:`SECRET_FILE`).

    Raises
    ------
    TokenError
        No such file (not a run started by this version of ``dfrl run``?), or an unsafe one.
    """
    path = Path(results_dir) / SECRET_FILE
    if not path.is_file():
        raise TokenError(
            f"{path} not found: the run's token is kept there (mode 0600) by "
            "dfrl run; is this the results folder of a running experiment?"
        )
    return read_token_file(path)
