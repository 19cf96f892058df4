"""Federated experiments: ``dfrl demo``, ``dfrl run CONFIG``, ``dfrl inject``, ``dfrl join``,
``dfrl collect`` and ``dfrl paper``.

``dfrl demo`` is the 5-robot dFRL demo on loopback (R1..R5, Q-learning, average, sync): five
robot processes, one itinerary agent, about a minute on a 2-core machine; it leaves the
plots, the CSVs and ``summary.md`` in ``results/demo`` and prints that path.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from typing import Any

from dfrl.experiments.driver.config import ConfigError, ExperimentConfig, resolve_config
from dfrl.experiments.cli.cluster import add_cluster_arguments
from dfrl.experiments.cli.tensorboard_option import add_tensorboard_argument, write_run_tensorboard
from dfrl.experiments.robot_host.config import Mode
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.tokens import TokenError, pop_env_tokens, read_token_file
from dfrl.experiments.driver.results.files import ClaimedFolder, claim_output, new_run_folder
from dfrl.experiments.driver.results.summary import Results


def add_override_arguments(p: argparse.ArgumentParser) -> None:
    """Flags that override fields of an experiment config (default: the config's value)."""
    g = p.add_argument_group("overrides (default: the config's value)")
    g.add_argument("--iterations", type=int, default=None, help="iterations per robot")
    g.add_argument("--respite", type=int, default=None, help="iterations between two shares")
    g.add_argument("--seed", type=int, default=None, help="experiment seed")
    g.add_argument(
        "--mode",
        choices=[m.value for m in Mode],
        default=None,
        help="async: robots flat out; sync: robots wait for the agent at each respite",
    )
    g.add_argument(
        "--rtf",
        type=_rtf,
        default=None,
        metavar="RTF|none",
        help="real-time factor, > 0 (1.0 = one iteration per 64 ms), or 'none': flat out",
    )
    g.add_argument("--method", default=None, help="aggregation method of every agent")
    g.add_argument("--timeout", type=float, default=None, help="experiment time limit (s)")


def _rtf(text: str) -> float | str:
    if text.lower() in ("none", "null"):
        return "none"
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"{text}: a real-time factor is > 0 ('none': flat out)")
    return value


def add_output_arguments(p: argparse.ArgumentParser, name: str) -> None:
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help=f"results folder; must not exist or be empty (default: a new "
        f"results/{name}/<timestamp>, with results/{name}/latest linked to it)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="empty a non-empty --out (a results folder) first (default: refuse)",
    )
    p.add_argument(
        "--view",
        action="store_true",
        help="serve a live web view of the run and print its URL (default: off)",
    )
    p.add_argument(
        "--view-port", type=int, default=0, help="port of the view (default: 0, the OS chooses)"
    )
    p.add_argument(
        "--view-host",
        default="127.0.0.1",
        help="address the view binds; another than loopback exposes it and "
        "needs --view-insecure (default: 127.0.0.1)",
    )
    p.add_argument(
        "--view-insecure",
        action="store_true",
        help="let --view-host be an address other than loopback although the "
        "page has no authentication (a warning is printed)",
    )
    from dfrl.experiments.cli.figures import add_figure_arguments

    add_figure_arguments(p)
    add_tensorboard_argument(p)


def add_tls_argument(p: argparse.ArgumentParser) -> None:
    """``--tls DIR``: mutual TLS for the driver's console node and its local robots."""
    p.add_argument(
        "--tls",
        type=Path,
        default=None,
        metavar="DIR",
        help="mutual TLS with the node certificate in DIR (ca.crt, node.crt, "
        "node.key from 'dfrl certs node'): the console node and every robot "
        "process spawned on this host use it (one credential for all local "
        'processes); remote robots ("robot_host": "HOST:PORT") must run '
        "'dfrl robot --tls' with a certificate of the same CA "
        "(default: none, plaintext)",
    )


def add_token_file_argument(p: argparse.ArgumentParser) -> None:
    """``--token-file FILE``: the run's token, instead of the config's or a random one."""
    p.add_argument(
        "--token-file",
        type=Path,
        default=None,
        metavar="FILE",
        help="the run's platform token, from FILE (mode 600; 'dfrl secret --out "
        "FILE' makes one), e.g. the token the remote robots were started with; "
        "or set DFRL_TOKEN (default: the config's token, else a random token "
        "of 256 bits). The run keeps it in secret.token (mode 600) of its "
        "results folder, for dfrl join and dfrl inject",
    )


def run_token(cfg: ExperimentConfig, args: argparse.Namespace) -> ExperimentConfig:
    """``cfg`` with the token of ``--token-file``, else of ``DFRL_TOKEN`` (taken out of this
    process's environment), else its own.

    Raises
    ------
    TokenError
        The file cannot be read, other users may read it, or it holds no token.
    """
    path = getattr(args, "token_file", None)
    tokens = read_token_file(path) if path is not None else pop_env_tokens()
    return cfg.with_token(tokens[0]) if tokens else cfg


def overrides_of(args: argparse.Namespace) -> dict[str, Any]:
    """The config keys the override flags that were given set."""
    changes: dict[str, Any] = {}
    for name, key in (
        ("iterations", "iterations"),
        ("respite", "respite"),
        ("seed", "seed"),
        ("mode", "mode"),
        ("timeout", "timeout_s"),
    ):
        v = getattr(args, name, None)
        if v is not None:
            changes[key] = v
    if getattr(args, "rtf", None) is not None:
        changes["rtf"] = None if args.rtf == "none" else args.rtf
    if getattr(args, "method", None) is not None:
        changes["method"] = args.method
        changes["methods"] = {}
    return changes


def print_results(results: Results) -> None:
    """Rounds, crashes on stderr; the results folder on stdout."""
    failed = [r for r in results.rounds if r.get("error")]
    partial = [r for r in results.rounds if r.get("skipped") and not r.get("error")]
    print(
        f"{len(results.rounds)} rounds, {results.equal_rounds} with every robot holding the "
        f"same table after the share, {len(partial)} that skipped robots, {len(failed)} "
        f"whose method FAILED; wall time {results.wall_time_s:.1f} s",
        file=sys.stderr,
    )
    if results.crashed:
        print(f"crashed robots: {results.crashed}", file=sys.stderr)
    if results.faults is not None:
        for line in results.faults.lines():
            print(line, file=sys.stderr)
        if not results.complete:
            print("the federation did NOT complete (see summary.md)", file=sys.stderr)
    print(results.output_dir)


def output_folder(args: argparse.Namespace, name: str) -> ClaimedFolder:
    """``--out`` (claimed: empty, or emptied with ``--force``), or a new timestamped folder;
    the launcher takes it as it is (claimed once).

    Raises
    ------
    FileExistsError
    """
    if args.out is not None:
        return ClaimedFolder(claim_output(args.out, args.force))
    return ClaimedFolder(new_run_folder(Path("results"), name))


def run_and_report(
    cfg: ExperimentConfig, args: argparse.Namespace, prog: str, show_summary: bool = False
) -> int:
    """Check ``cfg`` and the TLS folder, claim the results folder, run it and report; the
    command's exit code (2: an unsafe or incomplete --cluster access, bad config, TLS folder
    or results folder, before anything started; 130: interrupted)."""
    from dfrl.experiments.cli.cluster import cluster_access_of, run_experiment_for
    from dfrl.experiments.tls_folder import CertError, check_node_dir

    tls = getattr(args, "tls", None)
    view_warning = None
    if getattr(args, "view", False):
        from dfrl.experiments.cli.view import view_exposure

        refusal, view_warning = view_exposure(
            args.view_host, args.view_insecure, "--view-host", "--view-insecure"
        )
        if refusal:
            print(f"{prog}: {refusal}; nothing was started", file=sys.stderr)
            return 2
    try:
        cluster_access_of(args)  # a plaintext cluster off loopback: refused first
    except ExperimentError as exc:
        print(f"{prog}: {exc}; nothing was started", file=sys.stderr)
        return 2
    try:
        cfg = run_token(cfg, args)
    except TokenError as exc:
        print(f"{prog}: --token-file: {exc}; nothing was started", file=sys.stderr)
        return 2
    try:
        cfg.check()
        if tls is not None:
            tls = check_node_dir(tls).resolve()
        claimed = output_folder(args, cfg.name)
        out = claimed.path
    except ConfigError as exc:
        return config_error(prog, exc)
    except CertError as exc:
        print(f"{prog}: --tls: {exc}; nothing was started", file=sys.stderr)
        return 2
    except FileExistsError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 2
    view = None
    if getattr(args, "view", False):
        from dfrl.experiments.tools.view import start_view

        from dfrl.experiments.cli.ports import is_address_in_use, port_in_use_text

        try:
            view = start_view(out, args.view_host, args.view_port, fresh=True)
        except OSError as exc:
            why = (
                port_in_use_text(args.view_host, args.view_port, "another dfrl view", "--view-port")
                if is_address_in_use(exc)
                else f"the view cannot serve on {args.view_host}:{args.view_port}: {exc}"
            )
            print(f"{prog}: {why}; nothing was started", file=sys.stderr)
            return 2
        if view_warning:
            print(f"{prog}: {view_warning}", file=sys.stderr, flush=True)
        print(f"{prog}: live view at {view.url}", file=sys.stderr, flush=True)
    try:
        results = run_experiment_for(args, cfg, claimed, tls)
    except ExperimentError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 1
    finally:
        if view is not None:
            view.close()
    from dfrl.experiments.cli.figures import redraw_experiment

    redraw_experiment(results.output_dir, args, cfg.default_title(), prog)
    write_run_tensorboard(results, args, prog)
    summary = results.output_dir / "summary.md"
    if show_summary and summary.is_file():
        print(summary.read_text(encoding="utf-8"), file=sys.stderr)
    print_results(results)
    if results.interrupted:
        kept = (
            sorted(p.name for p in (out / "tables").glob("*.npy"))
            if (out / "tables").is_dir()
            else []
        )
        print(
            f"{prog}: interrupted ({results.interrupted}); kept in {out}: summary.md, "
            f"metrics.csv, rounds.csv and {len(kept)} table file(s) in tables/"
            + (
                f" (from checkpoints: {', '.join(results.from_checkpoint)})"
                if results.from_checkpoint
                else ""
            ),
            file=sys.stderr,
        )
        return 130
    return 0 if results.ok else 1


def config_error(prog: str, exc: ConfigError) -> int:
    """Print every problem of a config, one per line; exit status 2."""
    n = len(exc.problems)
    print(
        f"{prog}: the config has {n} problem{'s' if n != 1 else ''}; nothing was started",
        file=sys.stderr,
    )
    for line in exc.text().splitlines():
        print(f"  {line}", file=sys.stderr)
    return 2


def cmd_demo(args: argparse.Namespace) -> int:
    """``dfrl demo``: the shipped ``demo`` config at the demo budget."""
    from dfrl.robots.training import DEMO_ITERATIONS

    try:
        over = {"iterations": DEMO_ITERATIONS, **overrides_of(args)}
        cfg = ExperimentConfig.load(resolve_config("demo"), over)
    except ConfigError as exc:
        return config_error("dfrl demo", exc)
    arenas = ", ".join(r.arena.upper() for r in cfg.robots)
    print(
        f"dfrl demo: {len(cfg.robots)} robots ({arenas}), "
        f"{cfg.method}, {cfg.iterations} iterations, a share every {cfg.respite} "
        f"({cfg.rounds} rounds), {cfg.mode.value} mode, seed {cfg.seed}",
        file=sys.stderr,
    )
    return run_and_report(cfg, args, "dfrl demo", show_summary=True)


def cmd_run(args: argparse.Namespace) -> int:
    try:
        cfg = ExperimentConfig.load(resolve_config(args.config), overrides_of(args))
    except FileNotFoundError as exc:
        print(f"dfrl run: {exc}", file=sys.stderr)
        return 2
    except ConfigError as exc:
        return config_error("dfrl run", exc)
    return run_and_report(cfg, args, "dfrl run")


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add ``demo`` and ``run`` (``inject``, ``join``, ``collect``: :mod:`.running`;
    ``paper``: :mod:`.studies`)."""
    p = subparsers.add_parser(
        "demo",
        help="the 5-robot dFRL demo on loopback (plots + summary "
        "in results/demo/<timestamp>); exit 1 unless the "
        "federation completed, 2 on a bad option",
    )
    add_output_arguments(p, "demo")
    add_tls_argument(p)
    add_token_file_argument(p)
    add_override_arguments(p)
    p.set_defaults(func=cmd_demo)

    p = subparsers.add_parser(
        "run",
        help="run a federated experiment (robot processes + agent); "
        "exit 1 unless the federation completed, 2 on a bad "
        "config (nothing started), 130 when interrupted",
    )
    p.add_argument("config", help="experiment config: a JSON file or a name in experiments/configs")
    add_output_arguments(p, "NAME")
    add_tls_argument(p)
    add_token_file_argument(p)
    add_override_arguments(p)
    add_cluster_arguments(p)
    p.set_defaults(func=cmd_run)
