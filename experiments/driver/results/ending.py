"""The files the end of a run writes, from what the folder holds and what the writer knew of
the run: :func:`write_end_files`. The driver calls it when a run ends
(``Launcher._collect``), ``dfrl collect`` when the driver did not get there (a driver that
was killed); both write the same files: ``tables/`` (``params/``) made whole from the last
checkpoints, ``metrics.csv``, ``live_evaluations.csv``, ``rounds.csv``, the tidy tables
(``tidy/``, :mod:`.tidy`), the plots and
``summary.md`` with its verdict, which includes the history checker's (:mod:`.history`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from dfrl.experiments.driver.config import GRID, ExperimentConfig
from dfrl.experiments.driver.results.agent_log import AgentLog
from dfrl.experiments.driver.results.carried import (Distilled, Weight, fedavg_weights,
                                                     read_distillations, write_distillation_csv,
                                                     write_weights_csv)
from dfrl.experiments.driver.results.evaluations import merge_evaluations
from dfrl.experiments.driver.results.faults import assess
from dfrl.experiments.driver.results.files import read_json
from dfrl.experiments.driver.results.history import (HistoryInputError, HistoryVerdict,
                                                     approximate_robots, check_shares,
                                                     read_history)
from dfrl.experiments.driver.results.metrics import merge_metrics, read_metrics
from dfrl.experiments.driver.results.plots import plot_experiment
from dfrl.experiments.driver.results.rounds import Share, read_shares, write_rounds_csv
from dfrl.experiments.driver.results.summary import Results, write_summary
from dfrl.experiments.driver.results.tables import final_tables, learnt_path
from dfrl.experiments.driver.results.tidy import write_tidy_tables
from dfrl.experiments.driver.results.what_ran import planned_agents


@dataclass
class RunFacts:
    """What the writer knows of a run beyond its files (the driver: what it saw; ``dfrl
    collect``: what it found out afterwards).

    Attributes
    ----------
    wall_time_s : float
    ok : bool
        False when the run already failed for a reason of its own (interrupted, an error).
    interrupted : str or None
        Why the run was interrupted (a signal), if it was.
    crashed : dict
        robot -> exit code of its process.
    iterations : dict
        robot -> iterations it ran.
    lost : dict
        robot -> why it counts as lost (the verdict counts them).
    stalls, other : list of str
        Stalls, and other faults that make the run incomplete (files not gathered ...).
    gathered : dict
        robot -> result files fetched from its robot host.
    failed_joins : dict
        robot -> why it could not join.
    collected : list of str or None
        Set by ``dfrl collect``: the summary's lines on how the files were collected after
        the driver stopped and what could not be fetched.
    resumed : dict
        robot -> the checkpoint iterations it was resumed at after its robot host restarted.
    finished : list of str
        Robots that ran all their iterations (an agent that skips one afterwards missed
        nothing of it).
    start_error : str or None
        Why the run never got going: the launcher's step that failed before the agents were
        launched, and its error (the summary's status says it).
    """

    wall_time_s: float
    ok: bool = True
    interrupted: str | None = None
    crashed: dict[str, int] = field(default_factory=dict)
    iterations: dict[str, int] = field(default_factory=dict)
    lost: dict[str, str] = field(default_factory=dict)
    stalls: list[str] = field(default_factory=list)
    other: list[str] = field(default_factory=list)
    gathered: dict[str, list[str]] = field(default_factory=dict)
    failed_joins: dict[str, str] = field(default_factory=dict)
    collected: list[str] | None = None
    resumed: dict[str, list[int]] = field(default_factory=dict)
    finished: list[str] = field(default_factory=list)
    start_error: str | None = None


def write_end_files(out: Path, config: ExperimentConfig, robots: list[str],
                    logs: dict[str, AgentLog], budgets: dict[str, int], facts: RunFacts,
                    say: Callable[[str], None]) -> Results:
    """Write the end-of-run files of the results folder ``out`` and return the
    :class:`Results` (``ok``: ``facts.ok``, every agent finished, and the federation complete
    by :meth:`~.faults.Faults.complete`, which includes the history checker's verdict on the
    robots' shares: a violation, or a shares file it cannot read, makes it incomplete).

    Parameters
    ----------
    out : Path
    config : ExperimentConfig
    robots : list of str
        The run's robots, in order.
    logs : dict
        agent -> its round log as read now.
    budgets : dict
        agent -> the rounds it was to run.
    facts : RunFacts
    say : callable
        Takes one progress line (what was kept, torn tables, problems of the logs, plots).
    """
    from_checkpoint, torn = final_tables(out, robots)
    for rid in from_checkpoint:
        kept = learnt_path(out, rid)
        where = f"{kept.parent.name}/{kept.name}" if kept else f"tables/{rid}.npy"
        say(f"table of {rid} kept from its last checkpoint ({where})")
    for line in torn.values():
        say(f"TABLE {line}")
    merge_metrics(out, robots)
    merge_evaluations(out, robots)
    shares, history, history_lines = _check_history(out, robots)
    say(history.text() if history is not None else history_lines[0])
    logs, budgets = _with_unlaunched(config, logs, budgets)
    distilled, weights, record_problems = _write_carried(out, config, robots, shares)
    for line in record_problems:
        say(line)
    rows = write_rounds_csv(out / "rounds.csv", logs.values(), robots, shares)
    for line in write_tidy_tables(out, config, robots)[1]:
        say(line)
    plots: list[Path] = []
    plot_error = None
    try:
        plots = plot_experiment(out, title=config.default_title())
    except ImportError as exc:
        plot_error = f"not drawn: {exc.name or 'matplotlib'} is not installed " \
                     "(pip install 'dfrl[plot]')"
    except Exception as exc:  # noqa: BLE001 - plots are optional, results are not
        plot_error = f"failed: {exc!r}"
    if plot_error:
        say(f"plots {plot_error}")
    finished = {n: lg.finished for n, lg in logs.items()}
    problems = {n: [f"round {a.round} aborted: {a.error}" for a in lg.aborted]
                + [f"unreadable line: {u}" for u in lg.unreadable]
                for n, lg in logs.items()}
    for name, lines in problems.items():
        for line in lines:
            say(f"{name}: {line}")
    faults = assess(config, [(lg, budgets[n]) for n, lg in logs.items()], facts.lost,
                    facts.stalls, facts.other, facts.resumed, facts.finished, shares,
                    ended_short(out, config, robots, facts.iterations), history_lines)
    ok = facts.ok and all(v is not None for v in finished.values()) and faults.complete(config)
    result = Results(out, config, facts.wall_time_s, rows, facts.crashed, finished,
                     facts.iterations, plots, ok, facts.interrupted, problems, plot_error,
                     faults, facts.gathered, list(from_checkpoint), torn, facts.failed_joins,
                     facts.collected, history, facts.start_error, distilled, weights,
                     record_problems)
    write_summary(result)
    return result


def _with_unlaunched(config: ExperimentConfig, logs: dict[str, AgentLog],
                     budgets: dict[str, int]) -> tuple[dict[str, AgentLog], dict[str, int]]:
    """The logs and budgets with an empty log for every agent the config plans that was
    never launched (e.g. a robot host refused the token first): its rounds count as missing,
    so such a run is never called complete."""
    logs, budgets = dict(logs), dict(budgets)
    for agent, _, _ in planned_agents(config):
        if agent not in logs:
            logs[agent] = AgentLog(agent)
            budgets.setdefault(agent, config.rounds)
    return logs, budgets


def _write_carried(out: Path, config: ExperimentConfig, robots: list[str],
                   shares: dict[str, list[Share]]
                   ) -> tuple[list[Distilled], list[Weight], list[str]]:
    """Write ``distillation.csv`` (a grid federation, or any distilled write recorded) and
    ``fedavg_weights.csv`` (any FedAvg weight recorded) from the robots' records
    (:mod:`.carried`); return their rows and, for records that cannot be read, why."""
    problems = []
    distilled: list[Distilled] = []
    weights: list[Weight] = []
    try:
        distilled = read_distillations(out, robots)
        if distilled or config.federation == GRID:
            write_distillation_csv(out / "distillation.csv", distilled)
    except (ValueError, OSError) as exc:
        problems.append(f"distillation residuals not written: {exc}")
    try:
        weights = fedavg_weights(out, shares)
        if weights:
            write_weights_csv(out / "fedavg_weights.csv", weights)
    except (ValueError, OSError) as exc:
        problems.append(f"FedAvg weights not written: {exc}")
    return distilled, weights, problems


def _check_history(out: Path, robots: list[str]) -> tuple[dict[str, list[Share]],
                                                          HistoryVerdict | None, list[str]]:
    """The robots' shares, the history checker's verdict on them and its violations as
    lines; when a shares file cannot be read strictly: the shares read leniently (bad rows
    left out), no verdict, and one line saying why."""
    try:
        shares, torn = read_history(out, robots)
    except HistoryInputError as exc:
        lenient = {rid: read_shares(out / f"shares_{rid}.csv") for rid in robots}
        return lenient, None, [f"history not checked: {exc}"]
    verdict = check_shares(shares, torn, approximate_robots(out))
    return shares, verdict, [f"{v.kind.value}: {v.detail}" for v in verdict.violations]


def ended_short(out: Path, config: ExperimentConfig, robots: list[str],
                iterations: dict[str, int]) -> dict[str, str]:
    """robot -> "ended at iteration I of N" for each robot that ran fewer iterations than it
    was to. I: its last iteration in ``metrics.csv``, else ``iterations`` (what the writer
    knew); N: its node config's (``nodes/<robot>.json``), its checkpoint's, else the
    config's for a robot of the config (a robot whose plan is unknown is not judged)."""
    curves: dict[str, Any] = {}
    try:
        curves = read_metrics(out / "metrics.csv")
    except (OSError, ValueError, KeyError):
        pass
    own = {s.id for s in config.robots}
    out_lines: dict[str, str] = {}
    for rid in robots:
        cur = curves.get(rid)
        done = int(cur["iteration"].max()) if cur is not None and len(cur) else \
            iterations.get(rid)
        planned = _planned(out, rid) or (config.iterations if rid in own else None)
        if done is not None and planned is not None and done < planned:
            out_lines[rid] = f"ended at iteration {done} of {planned}"
    return out_lines


def _planned(out: Path, rid: str) -> int | None:
    """Iterations robot ``rid`` was to run, by its node config or its checkpoint."""
    for path in (out / "nodes" / f"{rid}.json", out / "checkpoint" / f"{rid}.json"):
        try:
            return int(read_json(path)["iterations"])
        except (OSError, ValueError, KeyError, TypeError):
            continue
    return None
