"""Where the robots on other hosts are and what travels to them: the address this host has
towards a robot host (:func:`route_source`), where the console node binds
(:func:`console_host`), an arena as configuration data (:func:`arena_payload`), and the check of
a file name a robot host lists (:func:`safe_relative`)."""

from __future__ import annotations

import json
import socket
from pathlib import Path, PurePosixPath
from typing import Any

from dfrl.experiments.driver.config import ExperimentConfig
from dfrl.experiments.errors import ExperimentError


def route_source(host: str, port: int = 9) -> str:
    """The local address this host uses towards ``host`` (its route's source address): the
    address at which a node of ours is reachable from there. No packet is sent.

    Raises
    ------
    ExperimentError
        ``host`` cannot be resolved or there is no route to it.
    """
    try:
        family = socket.getaddrinfo(host, port, type=socket.SOCK_DGRAM)[0]
        with socket.socket(family[0], socket.SOCK_DGRAM) as s:
            s.connect(family[4])
            return str(s.getsockname()[0])
    except OSError as exc:
        raise ExperimentError(f"no route to robot host {host}: {exc}") from None


def console_host(config: ExperimentConfig) -> str:
    """Where the launcher's console node (and every robot it spawns itself) binds: the
    config's ``console``; else the route's source address towards the first remote robot;
    else 127.0.0.1 (every robot on this host)."""
    if config.console:
        return config.console
    remote = config.remote_robots()
    if remote:
        host, port = remote[0].robot_host_address or ("127.0.0.1", 9)
        return route_source(host, port)
    return "127.0.0.1"


def arena_payload(arena: str) -> tuple[str, dict[str, Any] | None]:
    """The ``node.arena`` name and the ``arena`` object of a configuration: a built-in name
    goes as it is (object None), an arena file as its JSON object (named by its stem).

    Raises
    ------
    ExperimentError
        The file cannot be read or is not a JSON object.
    """
    path = Path(arena)
    if not path.is_file():
        return arena, None
    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ExperimentError(f"arena file {path}: {exc}") from None
    if not isinstance(obj, dict):
        raise ExperimentError(f"arena file {path}: not a JSON object")
    return path.stem, obj


def safe_relative(name: str) -> PurePosixPath:
    """A file name a robot listed, as a path inside the results folder.

    Raises
    ------
    ExperimentError
        An absolute name or one that climbs out (``..``).
    """
    p = PurePosixPath(name)
    if not name or p.is_absolute() or ".." in p.parts or "\\" in name:
        raise ExperimentError(f"robot listed a file outside its folder: {name!r}")
    return p


def short_of_clones(where: str, has: object, needs: int | None) -> None:
    """Refuse a robot host whose node admits fewer clones a minute (``has``, from its status;
    None from a service that does not say) than the run's robots need (``needs``: a tree
    itinerary's, :func:`~.spawn.clone_limit`; None for a chain).

    Raises
    ------
    ExperimentError
        Naming the host, both figures and the ``dfrl robot`` option that fixes it.
    """
    if needs is None or not isinstance(has, int) or has >= needs:
        return
    raise ExperimentError(
        f"robot host {where} admits {has} clones a minute, and this tree itinerary needs "
        f"{needs} (its copies are clones: with fewer, most rounds skip robots); start its "
        f"dfrl robot with --clone-limit {needs} or more"
    )
