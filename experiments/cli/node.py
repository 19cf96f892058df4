"""``dfrl node``: run one platform node in its own SWI-Prolog process."""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import dataclass
from typing import Callable, Union

from dfrl.experiments import processes
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.tls_folder import CertError, check_node_dir, is_node_name
from dfrl.experiments.tokens import (
    TOKEN_ENV,
    Token,
    env_with_tokens,
    parse_tokens,
    pop_env_tokens,
    read_token_file,
)
from dfrl.platform_pl import PLATFORM_DIR


Bound = Union[int, float, str]
"""A bound's value: a positive number, or ``"infinite"`` where the bound allows it."""


@dataclass(frozen=True)
class BoundFlag:
    """A command-line flag for a node option bounding agents or frames."""

    flag: str
    option: str
    integer: bool
    infinite: bool
    metavar: str
    help: str

    def parse(self, text: str) -> Bound:
        """The value of ``text``; raise argparse.ArgumentTypeError if it is not one."""
        if self.infinite and text == "infinite":
            return "infinite"
        try:
            value: int | float = int(text) if self.integer else float(text)
        except ValueError:
            value = -1
        if value <= 0:
            kind = "integer" if self.integer else "number"
            also = " or infinite" if self.infinite else ""
            raise argparse.ArgumentTypeError(f"needs a positive {kind}{also}, not {text!r}")
        return value


#: Every node option that bounds what agents (or frames) may take, as flags of ``dfrl node``
#: and ``dfrl robot`` (node_start/3 documents them; platform_pl/README.md "Bounds on agents").
BOUND_FLAGS: tuple[BoundFlag, ...] = (
    BoundFlag(
        "--agent-cpu-limit",
        "agent_cpu_limit",
        False,
        True,
        "SEC",
        "CPU seconds of one handler call of an agent (default 2)",
    ),
    BoundFlag(
        "--agent-stack-limit",
        "agent_stack_limit",
        True,
        True,
        "BYTES",
        "stacks of one handler call (default 268435456, 256 MiB)",
    ),
    BoundFlag(
        "--agent-module-limit",
        "agent_module_limit",
        True,
        True,
        "BYTES",
        "an agent's own code and facts (default 67108864, 64 MiB)",
    ),
    BoundFlag(
        "--agent-post-limit",
        "agent_post_limit",
        True,
        True,
        "N",
        "posts an agent sends per minute (default 600)",
    ),
    BoundFlag(
        "--agent-log-limit",
        "agent_log_limit",
        True,
        True,
        "N",
        "output lines per agent and minute (default 200)",
    ),
    BoundFlag("--max-agents", "max_agents", True, True, "N", "agents on the node (default 100)"),
    BoundFlag(
        "--clone-limit", "clone_limit", True, True, "N", "clones arriving per minute (default 60)"
    ),
    BoundFlag(
        "--agent-memory-budget",
        "agent_memory_budget",
        True,
        True,
        "BYTES",
        "what the node's agents hold together: modules plus stacks of running calls "
        "(default 1073741824, 1 GiB)",
    ),
    BoundFlag(
        "--max-running-agents",
        "max_running_agents",
        True,
        True,
        "N",
        "agent handler calls running at once; more wait (default 8)",
    ),
    BoundFlag(
        "--agent-slot-wait",
        "agent_slot_wait",
        False,
        False,
        "SEC",
        "how long a call waits for a running slot (default 60)",
    ),
    BoundFlag(
        "--agent-wall-limit",
        "agent_wall_limit",
        False,
        True,
        "SEC",
        "wall seconds one handler call may hold a running slot (default 60)",
    ),
    BoundFlag(
        "--agent-idle-limit",
        "agent_idle_limit",
        False,
        True,
        "SEC",
        "seconds an agent from a peer may stay idle before it is removed (default 600)",
    ),
    BoundFlag(
        "--max-agents-per-peer",
        "max_agents_per_peer",
        True,
        True,
        "N",
        "agents one peer may have on the node (default 50)",
    ),
    BoundFlag(
        "--max-running-per-peer",
        "max_running_per_peer",
        True,
        True,
        "N",
        "running slots the agents of one peer may hold at once (default 4)",
    ),
    BoundFlag(
        "--peer-post-limit",
        "peer_post_limit",
        True,
        True,
        "N",
        "posts one peer may deliver per minute (default 6000)",
    ),
    BoundFlag(
        "--max-frame-size",
        "max_frame_size",
        True,
        False,
        "BYTES",
        "largest frame from a peer that proved a token (default 33554432, 32 MiB)",
    ),
)


def add_bound_arguments(p: argparse.ArgumentParser) -> None:
    """One flag per entry of :data:`BOUND_FLAGS` (values may be ``infinite`` where noted)."""
    g = p.add_argument_group("bounds on agents (each may be 'infinite' unless noted)")
    for b in BOUND_FLAGS:
        parse: Callable[[str], Bound] = b.parse
        g.add_argument(
            b.flag,
            dest=b.option,
            type=parse,
            default=None,
            metavar=b.metavar,
            help=b.help + ("" if b.infinite else "; not infinite"),
        )


def bounds_of_args(args: argparse.Namespace) -> dict[str, Bound]:
    """The bound options a command line gave, by node option name."""
    return {
        b.option: getattr(args, b.option)
        for b in BOUND_FLAGS
        if getattr(args, b.option, None) is not None
    }


def node_command(
    host: str = "localhost",
    port: int = 0,
    consult: list[str] | None = None,
    interactive: bool = False,
    advertise: str | None = None,
    store: str | None = None,
    insecure: bool = False,
    tls: str | None = None,
    tls_peers: list[str] | None = None,
    trust: list[str] | None = None,
    bounds: dict[str, Bound] | None = None,
) -> list[str]:
    """The ``swipl`` command line that runs one node. It holds no token: run it with the
    node's tokens in the environment (:func:`dfrl.experiments.tokens.env_with_tokens`; none:
    an open node, which warns on loopback and does not start elsewhere).

    Parameters
    ----------
    host, port
        Address to listen on (port 0: the OS chooses; the node prints it).
    consult
        Agent programs to load before serving.
    interactive
        Open a Prolog toplevel on the node.
    advertise
        ``HOST[:PORT]`` other nodes reach this one at (default: the bound address, or the
        host name when bound to 0.0.0.0).
    store
        Folder where the node keeps its identity and custody records across restarts.
    insecure
        Accept a weak token (or none) on an address other than loopback.
    tls
        A node's TLS folder (``ca.crt``, ``node.crt``, ``node.key``; ``dfrl certs node``):
        every connection is mutual TLS; any token is then accepted off loopback.
    tls_peers
        With ``tls``: the certificate names that may send agents or code (default: any the
        CA signed).
    trust
        With ``tls``: certificate names whose code (agents, programs) is installed without
        the sandbox check (node option ``trusted_peers``; default: none, all code checked).
    bounds
        Node options bounding agents and frames, by name (:data:`BOUND_FLAGS`).

    Raises
    ------
    ValueError
        A port out of range, ``tls_peers`` or ``trust`` without ``tls``, a name no
        certificate can have, ``tls`` not a node TLS folder, or an unknown bound or bad
        value.
    ExperimentError
        ``swipl`` is missing.
    """
    if not 0 <= port <= 65535:
        raise ValueError(f"port {port} is outside 0..65535")
    cmd = [
        processes.swipl(),
        "-q",
        str(PLATFORM_DIR / "node_main.pl"),
        "--host",
        host,
        "--port",
        str(port),
    ]
    for path in consult or []:
        cmd += ["--consult", os.path.abspath(path)]
    if advertise:
        cmd += ["--advertise", advertise]
    if store:
        cmd += ["--store", os.path.abspath(store)]
    if insecure:
        cmd.append("--insecure")
    if tls_peers and not tls:
        raise ValueError("--tls-peer needs --tls")
    if trust and not tls:
        raise ValueError("--trust needs --tls (trust is by TLS certificate name)")
    check_trust_names(trust or [])
    if tls:
        try:
            cmd += ["--tls", str(check_node_dir(tls).resolve())]
        except CertError as exc:
            raise ValueError(str(exc)) from exc
    for name in tls_peers or []:
        cmd += ["--tls-peer", name]
    for name in trust or []:
        cmd += ["--trust", name]
    flags = {b.option: b for b in BOUND_FLAGS}
    for option, value in (bounds or {}).items():
        if option not in flags:
            raise ValueError(f"unknown bound {option!r}")
        try:
            flags[option].parse(str(value))
        except argparse.ArgumentTypeError as exc:
            raise ValueError(f"{flags[option].flag}: {exc}") from exc
        cmd += [flags[option].flag, str(value)]
    if interactive:
        cmd.append("--interactive")
    return cmd


def check_trust_names(names: list[str]) -> None:
    """Raise ValueError for a ``--trust`` name no node certificate can have (``dfrl certs``
    names: letters, digits, ``-`` and ``.``, at most 64 characters)."""
    for name in names:
        if not is_node_name(name):
            raise ValueError(
                f"--trust {name!r}: not a certificate name (letters, digits, "
                "'-' and '.', at most 64 characters, as 'dfrl certs node' makes)"
            )


def tokens_of_args(args: argparse.Namespace, prog: str) -> list[Token]:
    """The tokens a ``dfrl node``/``dfrl robot`` command line names: those of ``DFRL_TOKEN``
    (taken out of this process's environment), of each ``--token-file`` and of each
    ``--token`` (with a warning on stderr: ``ps`` shows it to every user).

    Raises
    ------
    TokenError
        A token file cannot be read, other users may read it, or holds no token.
    """
    tokens: list[Token] = []
    if args.token:
        print(
            f"{prog}: warning: --token puts the token on the command line, where other "
            "users of this host see it (ps); use --token-file FILE (mode 600) or the "
            f"environment variable {TOKEN_ENV}",
            file=sys.stderr,
        )
        tokens += parse_tokens("\n".join(args.token))
    for path in args.token_file:
        tokens += read_token_file(path)
    tokens += pop_env_tokens()
    return list(dict.fromkeys(tokens))


def add_token_arguments(p: argparse.ArgumentParser, what: str) -> None:
    """``--token-file FILE`` and ``--token T`` (both repeatable)."""
    p.add_argument(
        "--token-file",
        action="append",
        default=[],
        metavar="FILE",
        help=f"file of {what}, one per line, readable by you only (chmod 600; "
        f"'dfrl secret' prints a strong token); or set {TOKEN_ENV} (repeatable)",
    )
    p.add_argument(
        "--token",
        action="append",
        default=[],
        metavar="T",
        help="a token on the command line (repeatable): other users of the host "
        "see it (ps), so this warns; prefer --token-file or " + TOKEN_ENV,
    )


def _run(args: argparse.Namespace) -> int:
    try:
        tokens = tokens_of_args(args, "dfrl node")
        cmd = node_command(
            args.host,
            args.port,
            args.consult,
            args.interactive,
            args.advertise,
            args.store,
            args.insecure,
            args.tls,
            args.tls_peer,
            args.trust,
            bounds_of_args(args),
        )
    except (ValueError, ExperimentError) as exc:  # TokenError is a ValueError
        print(f"dfrl node: {exc}", file=sys.stderr)
        return 2
    # the node reads DFRL_TOKEN and deletes it from its environment
    os.execve(cmd[0], cmd, env_with_tokens(tokens))
    return 0  # not reached


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``node`` subcommand."""
    p = subparsers.add_parser("node", help="run one platform node (prints its address)")
    p.add_argument("--host", default="localhost", help="address to bind (default localhost)")
    p.add_argument("--port", type=int, default=0, help="port (default 0: the OS chooses)")
    add_token_arguments(
        p,
        "platform tokens an arriving agent or peer must prove (none: an "
        "open node, refused off loopback)",
    )
    p.add_argument(
        "--consult",
        action="append",
        default=[],
        metavar="FILE",
        help="agent program to load (repeatable)",
    )
    p.add_argument(
        "--advertise",
        default=None,
        metavar="HOST[:PORT]",
        help="address other nodes reach this one at (default: the bound one)",
    )
    p.add_argument(
        "--store",
        default=None,
        metavar="DIR",
        help="keep the node's identity and custody records in DIR (survive restarts)",
    )
    p.add_argument(
        "--insecure",
        action="store_true",
        help="accept a weak token (or none) on an address other than loopback (default: refused)",
    )
    p.add_argument(
        "--tls",
        default=None,
        metavar="DIR",
        help="mutual TLS with the node certificate in DIR (ca.crt, node.crt, "
        "node.key from 'dfrl certs node'); default: plaintext",
    )
    p.add_argument(
        "--tls-peer",
        action="append",
        default=[],
        metavar="NAME",
        help="with --tls: a certificate name that may send agents or code "
        "(repeatable; default: any name the CA signed)",
    )
    add_trust_argument(p)
    add_bound_arguments(p)
    p.add_argument("--interactive", action="store_true", help="open a Prolog toplevel on the node")
    p.set_defaults(func=_run)


def add_trust_argument(p: argparse.ArgumentParser) -> None:
    """``--trust NAME`` (repeatable): code from that certificate name skips the sandbox."""
    p.add_argument(
        "--trust",
        action="append",
        default=[],
        metavar="NAME",
        help="with --tls: install agents and programs from the peer whose "
        "certificate names NAME without the sandbox check (repeatable; "
        "default: none, all code from peers is checked)",
    )
