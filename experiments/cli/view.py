"""``dfrl view RESULTS_DIR``: serve the live view of a results folder (a finished run, with
its replay slider, or one still going on) until Ctrl-C."""

from __future__ import annotations

import argparse
import ipaddress
import sys
import time
from pathlib import Path

from dfrl.experiments.cli.ports import is_address_in_use, port_in_use_text


def is_loopback(host: str) -> bool:
    """``host`` is ``localhost`` or a loopback address (127.0.0.0/8, ``::1``): only this host
    reaches it. Any other name or address counts as reachable from elsewhere."""
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def view_exposure(
    host: str, insecure: bool, host_option: str, insecure_option: str
) -> tuple[str | None, str | None]:
    """Whether the view may bind ``host``: ``(refusal, warning)``, at most one of them set.
    The page has no authentication (no token, no TLS: anyone who reaches the port reads the
    run's nodes, curves and events), so an address other than loopback is refused unless
    ``insecure`` (``insecure_option`` given), and then warned about."""
    if is_loopback(host):
        return None, None
    if not insecure:
        return (
            f"{host_option} {host} would serve the run's page, which has no "
            f"authentication, to everyone who reaches this host; keep 127.0.0.1 and "
            f"reach it through an SSH tunnel (ssh -L PORT:127.0.0.1:PORT THIS_HOST), or "
            f"give {insecure_option} to serve it anyway"
        ), None
    return None, (
        f"WARNING: the view on {host} has no authentication ({insecure_option}): "
        f"everyone who reaches this host reads the run's nodes, curves and events"
    )


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "view",
        help="serve the web view of a results folder (live or finished run)",
        description="Serve the web page of a run's results folder: its nodes, the agent's "
        "path, the curves, the events, with a replay slider. Until Ctrl-C.",
    )
    p.add_argument("results_dir", metavar="RESULTS_DIR")
    p.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to bind (default 127.0.0.1; another one must be asked for)",
    )
    p.add_argument("--port", type=int, default=0, help="port (default: one the OS chooses)")
    p.add_argument(
        "--insecure",
        action="store_true",
        help="serve on an address other than loopback although the page has no "
        "authentication (a warning is printed; default: refused)",
    )
    p.set_defaults(func=cmd_view)


def cmd_view(args: argparse.Namespace) -> int:
    from dfrl.experiments.tools.view import start_view

    out = Path(args.results_dir)
    if not (out / "config.json").is_file():
        print(f"dfrl view: {out} is not a results folder (no config.json)", file=sys.stderr)
        return 2
    refusal, warning = view_exposure(args.host, args.insecure, "--host", "--insecure")
    if refusal:
        print(f"dfrl view: {refusal}", file=sys.stderr)
        return 2
    if warning:
        print(f"dfrl view: {warning}", file=sys.stderr, flush=True)
    try:
        view = start_view(out, host=args.host, port=args.port)
    except OSError as exc:
        why = (
            port_in_use_text(args.host, args.port, "another dfrl view", "--port")
            if is_address_in_use(exc)
            else f"cannot serve on {args.host}:{args.port}: {exc}"
        )
        print(f"dfrl view: {why}", file=sys.stderr)
        return 1
    print(f"dfrl view of {out} at {view.url} (Ctrl-C stops)", flush=True)
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        pass
    finally:
        view.close()
    return 0
