"""``dfrl run --cluster ADDRESS`` (and ``dfrl paper --cluster``): the run's robots placed on a
Dask cluster (:mod:`dfrl.experiments.driver.launcher.cluster`) instead of spawned on the
driver's host.

Only the options and the choice of backend live here; ``dfrl run`` (:mod:`.federated`) calls
:func:`run_experiment_for` where it would call the launcher. Without ``--cluster`` nothing of
the engine is imported (``dfrl demo`` does not need it).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from dfrl.experiments.driver.config import ExperimentConfig
from dfrl.experiments.driver.results.files import ClaimedFolder
from dfrl.experiments.driver.results.summary import Results


def add_cluster_arguments(p: argparse.ArgumentParser) -> None:
    """``--cluster ADDRESS``, ``--cluster-tls DIR``, ``--insecure`` and ``--cluster-cpus N``
    of ``dfrl run``."""
    g = p.add_argument_group("cluster (README: 'Running on a cluster')")
    g.add_argument(
        "--cluster",
        default=None,
        metavar="ADDRESS",
        help="place every robot without robot_host on the Dask cluster whose "
        "scheduler is ADDRESS (e.g. tls://10.0.0.1:8786, with --cluster-tls): "
        "each starts a dfrl robot service on a worker's host (needs pip "
        "install 'dfrl[cluster]', --token-file, and dfrl.token beside every "
        "worker)",
    )
    g.add_argument(
        "--cluster-tls",
        type=Path,
        default=None,
        metavar="DIR",
        help="with a tls:// --cluster: this host's cluster certificate folder "
        "(ca.crt, cluster.crt, cluster.key: 'dfrl certs cluster NAME CA_DIR "
        "--out DIR')",
    )
    g.add_argument(
        "--insecure",
        action="store_true",
        help="accept a plaintext tcp:// --cluster off loopback (refused otherwise: "
        "anyone who reaches such a scheduler runs code on its workers)",
    )
    g.add_argument(
        "--cluster-cpus",
        type=_positive,
        default=1.0,
        metavar="N",
        help="the CPU resource each robot asks the cluster for (default 1; workers "
        "offer it with dask worker --resources CPU=N)",
    )


def add_study_cluster_arguments(p: argparse.ArgumentParser) -> None:
    """``--cluster``, ``--cluster-cpus`` and ``--token-file`` of a study: its federated runs'
    robots on the cluster."""
    add_cluster_arguments(p)
    p.add_argument(
        "--token-file",
        type=Path,
        default=None,
        metavar="FILE",
        help="with --cluster: the token the workers' robot services prove (the "
        "dfrl.token beside every worker)",
    )


def cluster_access_of(args: argparse.Namespace) -> Any:
    """The :class:`~dfrl.experiments.driver.launcher.cluster.ClusterAccess` of ``--cluster``,
    ``--cluster-tls`` and ``--insecure`` (None without ``--cluster``). Imports no engine.

    Raises
    ------
    ClusterAccessError
        As :func:`~dfrl.experiments.driver.launcher.cluster.cluster_access`, or
        ``--cluster-tls`` / ``--insecure`` without ``--cluster``.
    """
    from dfrl.experiments.driver.launcher.cluster import ClusterAccessError, cluster_access

    address = getattr(args, "cluster", None)
    if address is None:
        for flag, given in (
            ("--cluster-tls", getattr(args, "cluster_tls", None) is not None),
            ("--insecure", getattr(args, "insecure", False)),
        ):
            if given:
                raise ClusterAccessError(f"{flag} is for --cluster ADDRESS")
        return None
    return cluster_access(address, args.cluster_tls, args.insecure)


def study_cluster(args: argparse.Namespace) -> Any:
    """The study's :class:`~dfrl.experiments.science.cluster_runs.ClusterOptions` (None
    without ``--cluster``).

    Raises
    ------
    ValueError
        ``--cluster`` without a readable ``--token-file``, or ``--token-file`` alone; an
        unsafe or incomplete cluster access (:func:`cluster_access_of`).
    """
    from dfrl.experiments.driver.launcher.cluster import ClusterAccessError
    from dfrl.experiments.science.cluster_runs import ClusterOptions
    from dfrl.experiments.tokens import TokenError, read_token_file

    try:
        access = cluster_access_of(args)
    except ClusterAccessError as exc:
        raise ValueError(f"{exc}; nothing was started") from None
    if access is None:
        if args.token_file is not None:
            raise ValueError("--token-file is for --cluster (the workers' token)")
        return None
    if args.token_file is None:
        raise ValueError(
            "--cluster needs --token-file FILE: the token of the dfrl.token beside every worker"
        )
    try:
        read_token_file(args.token_file)
    except TokenError as exc:
        raise ValueError(f"--token-file: {exc}") from None
    return ClusterOptions(
        access.address,
        args.token_file.resolve(),
        args.cluster_cpus,
        tls=access.tls,
        insecure=args.insecure,
    )


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
    return value


def run_experiment_for(
    args: argparse.Namespace, cfg: ExperimentConfig, claimed: ClaimedFolder, tls: Path | None
) -> Results:
    """Run ``cfg`` into ``claimed``: on the cluster of ``--cluster`` if given, else with the
    launcher alone.

    Raises
    ------
    ExperimentError
        As :func:`dfrl.experiments.driver.launcher.run` and, with ``--cluster``,
        :func:`dfrl.experiments.driver.launcher.cluster.run_on_cluster`.
    """
    address = getattr(args, "cluster", None)
    if address is None:
        from dfrl.experiments.driver.launcher import run

        return run(cfg, claimed, tls=tls)
    from dfrl.experiments.driver.launcher.cluster import run_on_cluster

    return run_on_cluster(
        cfg,
        claimed,
        address,
        cpus=args.cluster_cpus,
        tls=tls,
        cluster_tls=args.cluster_tls,
        insecure=args.insecure,
    )
