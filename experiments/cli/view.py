"""``dfrl view RESULTS_DIR``: serve the live view of a results folder (a finished run, with
its replay slider, or one still going on) until Ctrl-C."""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "view", help="serve the web view of a results folder (live or finished run)",
        description="Serve the web page of a run's results folder: its nodes, the agent's "
                    "path, the curves, the events, with a replay slider. Until Ctrl-C.")
    p.add_argument("results_dir", metavar="RESULTS_DIR")
    p.add_argument("--host", default="127.0.0.1",
                   help="address to bind (default 127.0.0.1; another one must be asked for)")
    p.add_argument("--port", type=int, default=0, help="port (default: one the OS chooses)")
    p.set_defaults(func=cmd_view)


def cmd_view(args: argparse.Namespace) -> int:
    from dfrl.experiments.tools.view import start_view

    out = Path(args.results_dir)
    if not (out / "config.json").is_file():
        print(f"dfrl view: {out} is not a results folder (no config.json)", file=sys.stderr)
        return 2
    try:
        view = start_view(out, host=args.host, port=args.port)
    except OSError as exc:
        print(f"dfrl view: cannot serve on {args.host}:{args.port}: {exc}", file=sys.stderr)
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
