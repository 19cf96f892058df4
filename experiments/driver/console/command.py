"""The command line that starts an experiment's console node (a ``swipl`` process running
``platform_pl/dfrl_agent/dfrl_console.pl``;
:class:`dfrl.experiments.driver.console.node.ConsoleNode` drives it)."""

from __future__ import annotations

import os
from pathlib import Path

from dfrl.experiments import processes
from dfrl.experiments.tls_folder import check_node_dir
from dfrl.platform_pl import DFRL_AGENT_DIR

CONSOLE_SCRIPT: Path = DFRL_AGENT_DIR / "dfrl_console.pl"
"""The Prolog program a console node runs."""


def console_command(
    host: str, port: int, tls: str | os.PathLike[str] | None = None, swipl: str | None = None
) -> list[str]:
    """The argv of a console node bound to ``host:port`` (0: the OS chooses). It holds no
    token: the node reads its tokens from ``DFRL_TOKEN`` in its environment
    (:func:`dfrl.experiments.tokens.env_with_tokens`), as ``ps`` shows every argv to every
    user.

    Parameters
    ----------
    tls : path or None
        A node's TLS folder (``ca.crt``, ``node.crt``, ``node.key``; ``dfrl certs node``): the
        node speaks mutual TLS on every connection (None: plaintext). Passed as an absolute
        path, so the node finds it whatever its working directory.
    swipl : str or None
        The ``swipl`` executable (default: found on ``PATH``).

    Raises
    ------
    ExperimentError
        ``swipl`` is missing.
    CertError
        ``tls`` does not hold the three files.
    """
    cmd = [
        swipl or processes.swipl(),
        "-q",
        str(CONSOLE_SCRIPT),
        "--host",
        host,
        "--port",
        str(int(port)),
    ]
    if tls is not None:
        cmd += ["--tls", str(check_node_dir(tls).resolve())]
    return cmd
