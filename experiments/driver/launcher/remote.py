"""Acting on a running experiment from another process: ``dfrl inject`` and ``dfrl join``."""

from __future__ import annotations

import time
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

from dfrl.experiments.config_rules import raise_problems
from dfrl.experiments.driver.config import RobotSpec
from dfrl.experiments.errors import ExperimentError
from dfrl.experiments.driver.console.channel import ConsoleRequestError
from dfrl.experiments.driver.launcher.agents import open_console, send_control
from dfrl.experiments.driver.launcher.joins import check_join
from dfrl.experiments.driver.launcher.remote_hosts import route_source
from dfrl.experiments.driver.results.agent_log import ControlEvent, read_rounds_log
from dfrl.experiments.driver.results.files import read_json
from dfrl.experiments.tls_folder import CertError, check_node_dir
from dfrl.experiments.tokens import Token, TokenError, run_tokens


def nodes_of(results_dir: str | Path) -> dict[str, Any]:
    """The ``nodes.json`` of a (running) experiment.

    Raises
    ------
    ExperimentError
        There is no ``nodes.json`` in ``results_dir``.
    """
    path = Path(results_dir) / "nodes.json"
    if not path.is_file():
        raise ExperimentError(f"{path} not found: is an experiment running there?")
    return read_json(path)


def finished_at(results_dir: str | Path) -> str | None:
    """When the run of ``results_dir`` ended, as ``2026-12-04 13:47:36 UTC``, or None while it
    has not: a run that ended (done, interrupted, or collected by ``dfrl collect`` after its
    driver stopped) has a ``summary.md``, which nothing writes before its end; the time is
    that file's."""
    summary = Path(results_dir) / "summary.md"
    try:
        mtime = summary.stat().st_mtime
    except OSError:
        return None
    return datetime.fromtimestamp(mtime, tz=timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC")


def require_running(results_dir: str | Path, what: str) -> None:
    """Refuse to act on a run that ended: ``what`` (``"inject into"``) says what was asked.

    Raises
    ------
    ExperimentError
        ``run NAME (DIR) finished at TIME; nothing to inject into ...``.
    """
    when = finished_at(results_dir)
    if when is None:
        return
    try:
        name = read_json(Path(results_dir) / "config.json").get("name")
    except (OSError, ValueError, AttributeError):
        name = None
    raise ExperimentError(
        f"run {name or Path(results_dir).name} ({results_dir}) finished at "
        f"{when} (its summary.md); nothing to {what} (dfrl inject and dfrl "
        f"join act on a run that is still going)"
    )


def unreachable(exc: BaseException) -> bool:
    """``exc`` is the console node failing to connect to a node (nobody listens there):
    ``transport_error(Address, connect(Detail))``."""
    return (
        isinstance(exc, ConsoleRequestError)
        and exc.formal_name == "transport_error"
        and len(exc.formal_args) == 2
        and exc.formal_args[1].startswith("connect(")
    )


def tokens_of(results_dir: str | Path) -> list[Token]:
    """The tokens of a (running) experiment: its ``secret.token`` (mode 0600; ``nodes.json``
    holds none), read each time, never copied.

    Raises
    ------
    ExperimentError
        No such file, or one other users may read.
    """
    try:
        return run_tokens(results_dir)
    except TokenError as exc:
        raise ExperimentError(str(exc)) from None


def driver_tls(
    results_dir: str | Path, info: dict[str, Any], tls: str | Path | None = None
) -> Path | None:
    """The TLS folder the driver's console node uses: ``tls`` when given (checked by the
    caller or here), else the one ``nodes.json`` records (None: a plaintext run).

    Raises
    ------
    CertError
        ``tls`` is not a node TLS folder.
    ExperimentError
        The recorded folder is not one on this host (e.g. the results folder was copied).
    """
    if tls is not None:
        return check_node_dir(tls).resolve()
    recorded = info.get("tls")
    if recorded is None:
        return None
    try:
        return check_node_dir(recorded).resolve()
    except CertError as exc:
        raise ExperimentError(
            f"{Path(results_dir) / 'nodes.json'} names the TLS folder "
            f"{recorded}, not usable here ({exc}); give this host's copy "
            "of the driver's certificate folder with --tls DIR"
        ) from exc


def rounds_log(results_dir: str | Path, agent: dict[str, Any]) -> Path:
    """The agent's round log: the path ``nodes.json`` names, or that file in ``results_dir``."""
    named = Path(agent.get("rounds_log") or f"rounds_{agent['name']}.log")
    return named if named.is_file() else Path(results_dir) / named.name


def _controls(path: Path, agent: str, command: str) -> list[ControlEvent]:
    return [c for c in read_rounds_log(path, agent).controls if c.command == command]


def inject_method(
    results_dir: str | Path,
    program: str | Path,
    method: str,
    agent: str | None = None,
    wait_s: float = 120.0,
    poll_s: float = 0.2,
    tls: str | Path | None = None,
) -> dict[str, str]:
    """Load ``program`` into every node of the running experiment, tell the agent(s) to switch
    to ``method``, and wait until each agent acknowledged it in its round log (the ``control``
    event it writes when it takes the command at its next round start). The program is loaded
    into every node of the agents' itineraries first; only once all loaded it is the driver
    told (it keeps the program in ``programs/`` and loads it into robots that join later) and
    the command sent. A program a node refuses (syntax error, with its file and line; the
    sandbox) is stored nowhere and changes no agent's method.
    Returns agent -> ``"applied"``, or ``"sent"`` for an agent that did not answer within
    ``wait_s`` (0: do not wait). ``tls``: the driver's TLS folder, instead of the one
    ``nodes.json`` records.

    Raises
    ------
    ExperimentError
        The run finished (:func:`require_running`), no such program or agent, no usable
        TLS folder (:func:`driver_tls`) or token file
        (:func:`tokens_of`), a node refused the program (the message says why), a control
        command failed, or an agent ignored the command (the message says why, e.g. the
        method is unknown on its node).
    """
    info = nodes_of(results_dir)
    require_running(results_dir, "inject into")
    tls_dir = driver_tls(results_dir, info, tls)
    prog = Path(program).resolve()
    if not prog.is_file():
        raise ExperimentError(f"program {prog} not found")
    targets = [a for a in info["agents"] if agent is None or a["name"] == agent]
    if not targets:
        known = ", ".join(a["name"] for a in info["agents"])
        raise ExperimentError(f"no agent {agent!r} in {results_dir} (agents: {known})")
    command = f"method({method})" if method.isidentifier() else f"method('{method}')"
    seen = {
        a["name"]: len(_controls(rounds_log(results_dir, a), a["name"], command)) for a in targets
    }
    first = targets[0]["itinerary"][0]
    with open_console(
        tokens_of(results_dir), host=route_source(first["host"], int(first["port"])), tls=tls_dir
    ) as console:
        for a in targets:  # loaded everywhere first: a refused program goes no further
            nodes = [(s["host"], s["port"]) for s in a["itinerary"]]
            try:
                console.load_program(prog, nodes)
            except ExperimentError as exc:
                why = str(exc).removeprefix("load_program failed: ")
                if unreachable(exc):
                    raise ExperimentError(
                        f"nothing injected: {why}; the run's nodes do not answer, yet it has "
                        f"no summary.md: its driver may have stopped (dfrl collect "
                        f"{results_dir} writes its end-of-run files)"
                    ) from None
                raise ExperimentError(
                    f"program {prog.name} refused, nothing injected (the "
                    f"agents keep their method): {why}"
                ) from None
        if info.get("console"):  # the driver gives the program to robots that join later
            console.announce_program(tuple(info["console"]), prog)
        for a in targets:
            nodes = [(s["host"], s["port"]) for s in a["itinerary"]]
            send_control(console, nodes[0], a["name"], {"method": method})
    status = {a["name"]: "sent" for a in targets}
    deadline = time.monotonic() + wait_s
    while wait_s > 0 and "sent" in status.values() and time.monotonic() < deadline:
        for a in targets:
            name = a["name"]
            if status[name] != "sent":
                continue
            path = rounds_log(results_dir, a)
            new = _controls(path, name, command)[seen[name] :]
            if new:
                if new[0].status != "applied":
                    raise ExperimentError(
                        f"agent {name} ignored method {method} (round "
                        f"{new[0].round}): {new[0].reason}"
                    )
                status[name] = "applied"
            elif read_rounds_log(path, name).finished is not None:
                raise ExperimentError(
                    f"agent {name} finished its tour before it took method {method}"
                )
        time.sleep(poll_s)
    return status


def join_robot(
    results_dir: str | Path,
    robot: str,
    arena: str,
    algo: str = "qlearning",
    iterations: int | None = None,
    seed: int | None = None,
    timeout_s: float = 60.0,
    node: str | None = None,
    tls: str | Path | None = None,
) -> dict[str, Any]:
    """Ask the launcher of a running experiment to start a robot and add it to the agent of
    its algorithm (from the agent's next round). Returns the new node's ``nodes.json`` entry.
    With ``node`` (``"HOST:PORT"`` of a running ``dfrl robot``) the launcher configures that
    service instead of starting a process. ``tls``: the driver's TLS folder, instead of the
    one ``nodes.json`` records.

    The launcher owns every process of an experiment: the request goes to its console node
    (``console`` in ``nodes.json``) as a platform post, and the launcher's answer comes back
    the same way.

    Raises
    ------
    ConfigError
        The request cannot be right (checked here before anything is sent or started,
        :func:`.joins.check_join`): an arena that does not exist or parse, an unknown
        algorithm or one no agent of the experiment learns with, a robot id taken or
        malformed, a malformed robot host; every problem at once.
    ExperimentError
        The run finished (:func:`require_running`), no usable TLS folder (:func:`driver_tls`)
        or token file (:func:`tokens_of`), the launcher
        refused, or no answer came in ``timeout_s``.
    """
    info = nodes_of(results_dir)
    require_running(results_dir, "join")
    entry: dict[str, Any] = {"id": robot, "arena": arena, "algo": algo}
    if seed is not None:
        entry["seed"] = seed
    if node is not None:
        entry["robot_host"] = node
    raise_problems(
        check_join(
            entry,
            [n["robot"] for n in info["nodes"]],
            {a["name"]: a["algo"] for a in info["agents"]},
        )
    )
    if not info.get("console"):
        raise ExperimentError(f"{results_dir}/nodes.json names no console node to ask")
    spec = RobotSpec(robot, arena, algo, seed, node)
    tls_dir = driver_tls(results_dir, info, tls)
    driver = tuple(info["console"])
    with open_console(
        tokens_of(results_dir), host=route_source(driver[0], int(driver[1])), tls=tls_dir
    ) as console:
        return console.request_join(tuple(info["console"]), spec, iterations, timeout_s=timeout_s)
