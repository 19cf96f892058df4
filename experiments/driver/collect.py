"""``dfrl collect``: write the end-of-run files of a run whose driver did not (it was killed,
its host went down), or again for a finished run: :func:`collect`.

The driver writes ``rounds.csv``, ``metrics.csv``, ``tables/`` (``params/``), the plots and
``summary.md`` when a run ends. When the driver dies first, what the run did is still there:
in the results folder (``config.json``, ``nodes.json``, the agents' ``rounds_<agent>.log``, and
for the robot processes of this host their ``metrics_<robot>.csv``, ``shares_<robot>.csv``,
``tables/``, ``checkpoint/`` and the round-log lines the agents logged on their nodes,
``agent_logs/<robot>/rounds_<agent>.log``) and on the robot hosts (each ``dfrl robot`` keeps
the files of the experiment it holds, its ``agent_logs/`` included). The agents' lines are
read from ``rounds_<agent>.log`` and every kept log, each line once: a round the console never
got (its driver was dead, its host cut off) is still counted. :func:`collect` fetches the
remote robots' files as the driver does at the end of a run
(:func:`~.launcher.remote_robots.fetch_files`, through a console node of its own with the
run's ``secret.token``), then writes the same files with the same code
(:func:`~.results.ending.write_end_files`). The verdict follows the same criteria, judged
from the files: a robot that did not run all its iterations counts as lost, a round never
logged as missing; ``summary.md`` says it was collected after the driver stopped and what
could not be fetched.

What a killed driver leaves running: the robot processes it spawned on its host read their
stdin's end of file as *stop*: each ends training at its next stdin check (every 50
iterations) or sooner, when a protocol line on its stdout (now a broken pipe) fails; it
saves ``tables/`` and its checkpoint when it gets to its end (a ``BrokenPipeError`` traceback
in ``logs/<robot>.err`` follows) and exits within seconds; none lingers. The console node
ends with its stdin too; the agent's lines then stay in its nodes' kept logs (and their
outboxes) until its robots are gone. ``dfrl robot`` services do not
depend on the driver: they run the experiment to its end and keep its files until they are
configured for another one.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path
from typing import Any, TextIO

from dfrl.experiments.driver.config import ConfigError, ExperimentConfig
from dfrl.experiments.driver.launcher.agents import agent_name, open_console
from dfrl.experiments.driver.launcher.remote import driver_tls, rounds_log, tokens_of
from dfrl.experiments.driver.launcher.remote_hosts import route_source
from dfrl.experiments.driver.launcher.remote_robots import fetch_files
from dfrl.experiments.driver.results.agent_log import AgentLog, kept_logs, read_rounds_log
from dfrl.experiments.driver.results.ending import RunFacts, write_end_files
from dfrl.experiments.driver.results.files import read_json
from dfrl.experiments.driver.results.metrics import read_metrics
from dfrl.experiments.driver.results.summary import Results
from dfrl.experiments.errors import ExperimentError

#: Seconds between two looks at robots that still run.
LOOK_S = 0.5


class NotAResultsFolder(ExperimentError):
    """The folder holds no readable ``config.json``: nothing to collect."""


def collect(
    results_dir: str | Path,
    progress: TextIO | None = sys.stderr,
    wait_s: float = 30.0,
    tls: str | Path | None = None,
) -> Results:
    """Fetch what a run's robot hosts hold and write its end-of-run files (see the module
    doc); idempotent. Robot processes of this host and robots on robot hosts still running
    the run get ``wait_s`` seconds to end; one still running then is reported and makes the
    verdict incomplete (collect again once it ended).

    Raises
    ------
    NotAResultsFolder
        No ``config.json`` in ``results_dir``, or one that is no experiment config.
    ExperimentError
        Remote robots to fetch from, but no usable token file or TLS folder.
    """
    out = Path(results_dir).resolve()
    config = _config(out)
    say = (
        (lambda line: print(f"dfrl collect: {line}", file=progress, flush=True))
        if progress is not None
        else (lambda line: None)
    )
    nodes = out / "nodes.json"
    info: dict[str, Any] = read_json(nodes) if nodes.is_file() else {"nodes": [], "agents": []}
    notes = [
        f"collected at {time.strftime('%Y-%m-%d %H:%M:%S')} by `dfrl collect` from the "
        "results folder"
        + (" and the robot hosts" if _remote(info) else "")
        + "; wall time is the span of the logged rounds"
    ]
    other: list[str] = []
    lost: dict[str, str] = {}
    if not nodes.is_file():
        notes.append("no nodes.json: the driver stopped before its robots were up")
    deadline = time.monotonic() + wait_s
    running = _wait_local(out, info, deadline)
    for rid, pid in running.items():
        other.append(
            f"{rid} was still running (pid {pid}) when collected: collect again once it ended"
        )
    status, gathered = (
        _fetch_remote(out, info, deadline, tls, notes, other, say) if _remote(info) else ({}, {})
    )
    robots = [str(n["robot"]) for n in info["nodes"]]
    for spec in config.robots:
        if spec.id not in robots:
            robots.append(spec.id)
            lost[spec.id] = "never came up (not in nodes.json)"
    iterations: dict[str, int] = {}
    finished: list[str] = []
    for rid in robots:
        if rid in lost:
            continue
        done, planned = _progress(out, rid, status.get(rid), config.iterations)
        if done is None:
            lost[rid] = "left no checkpoint and no metrics"
            continue
        iterations[rid] = done
        if planned is not None and done < planned and rid not in running:
            lost[rid] = f"stopped at iteration {done} of {planned}"
        elif planned is not None and done >= planned:
            finished.append(rid)
    logs: dict[str, AgentLog] = {}
    budgets: dict[str, int] = {}
    for a in info["agents"]:
        own = out / f"rounds_{a['name']}.log"  # this folder's, even if it was moved
        logs[a["name"]] = read_rounds_log(
            own if own.is_file() else rounds_log(out, a), a["name"], kept=kept_logs(out, a["name"])
        )
        budgets[a["name"]] = int(a["rounds"])
    for label, algos in config.agent_groups():
        if agent_name(label) not in logs and any(s.algo in algos for s in config.robots):
            other.append(f"agent {agent_name(label)} was never launched (not in nodes.json)")
    spans = [t for lg in logs.values() for r in lg.rounds for t in (r.start, r.end)]
    wall = max(spans) - min(spans) if spans else 0.0
    facts = RunFacts(
        wall,
        iterations=iterations,
        lost=lost,
        other=other,
        gathered=gathered,
        collected=notes,
        finished=finished,
    )
    return write_end_files(out, config, robots, logs, budgets, facts, say)


def _config(out: Path) -> ExperimentConfig:
    path = out / "config.json"
    if not path.is_file():
        raise NotAResultsFolder(f"{out} is not a results folder (no config.json)")
    try:
        return ExperimentConfig.from_dict(read_json(path))
    except (ConfigError, ValueError, TypeError, KeyError) as exc:
        raise NotAResultsFolder(f"{path} is no experiment config: {exc}") from None


def _remote(info: dict[str, Any]) -> list[dict[str, Any]]:
    return [n for n in info["nodes"] if n.get("robot_host")]


def _alive(pid: int, config_path: Path) -> bool:
    """Process ``pid`` runs, is no zombie, and is the robot process of ``config_path``."""
    proc = Path(f"/proc/{pid}")
    try:
        cmdline = (proc / "cmdline").read_bytes().split(b"\0")
        state = (proc / "stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ("Z", "X") and os.fsencode(config_path) in cmdline


def _wait_local(out: Path, info: dict[str, Any], deadline: float) -> dict[str, int]:
    """Wait (until ``deadline``) for the robot processes of this host the run started; return
    those still running -> pid."""
    local = {
        str(n["robot"]): int(n["pid"])
        for n in info["nodes"]
        if not n.get("robot_host") and n.get("pid")
    }
    while True:
        running = {
            rid: pid for rid, pid in local.items() if _alive(pid, out / "nodes" / f"{rid}.json")
        }
        if not running or time.monotonic() >= deadline:
            return running
        time.sleep(LOOK_S)


def _fetch_remote(
    out: Path,
    info: dict[str, Any],
    deadline: float,
    tls: str | Path | None,
    notes: list[str],
    other: list[str],
    say: Any,
) -> tuple[dict[str, dict[str, Any]], dict[str, list[str]]]:
    """Fetch the files of the run's robots on robot hosts (waiting until ``deadline`` for
    those still running it); return (robot -> its last status, robot -> files fetched). What
    could not be fetched goes to ``notes``, and to ``other`` when the folder lacks it."""
    remote = _remote(info)
    first = remote[0]
    statuses: dict[str, dict[str, Any]] = {}
    gathered: dict[str, list[str]] = {}
    host = route_source(str(first["host"]), int(first["port"]))
    with open_console(
        tokens_of(out),
        out / "logs" / "collect_console.err",
        host=host,
        tls=driver_tls(out, info, tls),
    ) as console:
        for node in remote:
            rid, where = str(node["robot"]), str(node["robot_host"])
            service = (str(node["host"]), int(node["port"]))
            status: dict[str, Any] = {}
            why = None
            for _ in range(int(max(0.0, deadline - time.monotonic()) / LOOK_S) + 1):
                try:
                    status = console.robot(service, "status", timeout_s=10.0)
                except ExperimentError as exc:
                    why = f"robot host {where} did not answer: {exc}"
                    break
                if status.get("experiment") != info.get("experiment"):
                    why = (
                        f"robot host {where} holds experiment {status.get('experiment')!r}, "
                        f"not this run's ({info.get('experiment')})"
                    )
                    break
                if status.get("state") != "running" or time.monotonic() >= deadline:
                    break
                time.sleep(LOOK_S)
            if why is None:
                statuses[rid] = status
                if status.get("state") == "running":
                    other.append(
                        f"{rid} was still running on {where} (iteration "
                        f"{status.get('iteration')}) when collected: collect again "
                        "once it ended"
                    )
                try:
                    gathered[rid] = fetch_files(console, service, rid, out)
                    say(f"{len(gathered[rid])} files of {rid} fetched from {where}")
                    continue
                except ExperimentError as exc:
                    why = f"files of {rid} not fetched from {where}: {exc}"
            have = (out / f"metrics_{rid}.csv").is_file()
            notes.append(
                f"NOT FETCHED {rid}: {why}"
                + ("; the folder has its files from before" if have else "")
            )
            say(f"{rid}: {why}")
            if not have:
                other.append(f"files of {rid} not fetched: {why}")
    return statuses, gathered


def _progress(
    out: Path, rid: str, status: dict[str, Any] | None, iterations: int
) -> tuple[int | None, int | None]:
    """(iterations the robot ran, iterations it was to run) from its robot host's status, its
    checkpoint, or its metrics (planned: the config's; None when unknown)."""
    if status is not None and status.get("iterations"):
        return int(status.get("iteration") or 0), int(status["iterations"])
    cp = out / "checkpoint" / f"{rid}.json"
    try:
        meta = read_json(cp)
        return int(meta["iteration"]), int(meta.get("iterations") or iterations)
    except (OSError, ValueError, KeyError, TypeError):
        pass
    metrics = out / f"metrics_{rid}.csv"
    try:
        curve = read_metrics(metrics).get(rid) if metrics.is_file() else None
    except (OSError, ValueError):
        curve = None
    if curve is None or len(curve) == 0:
        return None, None
    return int(curve["iteration"][-1]), iterations
