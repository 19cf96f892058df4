"""What a run produced (:class:`Results`) and its ``summary.md``."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dfrl.experiments.driver.config import GRID, ExperimentConfig
from dfrl.experiments.driver.results.carried import Distilled, Weight
from dfrl.experiments.driver.results.evaluations import last_evaluations
from dfrl.experiments.driver.results.faults import Faults
from dfrl.experiments.driver.results.files import read_json
from dfrl.experiments.driver.results.history import HistoryVerdict
from dfrl.experiments.driver.results.metrics import read_metrics
from dfrl.experiments.driver.results.rounds import count_equal, count_unverified
from dfrl.experiments.driver.results.tables import params_path, table_sum
from dfrl.experiments.driver.results.what_ran import what_ran_lines
from dfrl.experiments.provenance import describe, read_provenance


@dataclass
class Results:
    """What :func:`dfrl.experiments.driver.launcher.run` produced."""

    output_dir: Path
    config: ExperimentConfig
    wall_time_s: float
    rounds: list[dict[str, Any]]
    crashed: dict[str, int]
    agents_finished: dict[str, int | None]
    iterations: dict[str, int]
    plots: list[Path]
    ok: bool
    interrupted: str | None = None
    log_problems: dict[str, list[str]] | None = None
    plot_error: str | None = None
    faults: Faults | None = None
    gathered: dict[str, list[str]] | None = None
    from_checkpoint: list[str] | None = None
    table_problems: dict[str, str] | None = None
    failed_joins: dict[str, str] | None = None
    #: set by ``dfrl collect``: how the files were collected after the driver stopped, and
    #: what could not be fetched (lines of the summary)
    collected: list[str] | None = None
    #: the history checker's verdict on the robots' shares (None: not checked, see
    #: ``faults.history``)
    history: HistoryVerdict | None = None
    #: why the run never got going (the launcher's step that failed and its error), when an
    #: error stopped it before its agents were launched
    start_error: str | None = None
    #: the distilled writes of a grid federation (``distillation.csv``)
    distilled: list[Distilled] | None = None
    #: every robot's weight per round of a FedAvg of parameters (``fedavg_weights.csv``)
    weights: list[Weight] | None = None
    #: robots' records of the shares that could not be read (lines of the summary)
    record_problems: list[str] | None = None

    @property
    def complete(self) -> bool:
        """The federation completed: every planned round done, no robot lost (up to what
        the config tolerates), the history of table writes kept its rules; see
        :meth:`Faults.complete`."""
        return self.faults is None or self.faults.complete(self.config)

    @property
    def equal_rounds(self) -> int:
        """Rounds after which every visited robot held the same table."""
        return count_equal(self.rounds)


def node_warnings(out_dir: Path) -> list[str]:
    """``Warning:`` / ``ERROR:`` lines the nodes and agent launchers printed (logs/)."""
    found = []
    for f in sorted((Path(out_dir) / "logs").glob("*")):
        try:
            text = f.read_text(encoding="utf-8", errors="replace")
        except OSError:
            continue
        found += [f"{f.stem}: {ln.strip()}" for ln in text.splitlines()
                  if ln.lstrip().startswith(("Warning:", "ERROR:"))]
    return found


def robot_kinds(out_dir: Path, config: ExperimentConfig) -> dict[str, tuple[str, str]]:
    """robot -> (arena, algo): the config's robots and joins, then the robots ``nodes.json``
    lists (a robot that joined through ``dfrl join`` is in no config), then the node configs
    (``nodes/<robot>.json``)."""
    kinds = {s.id: (s.arena, s.algo) for s in list(config.robots) + [j.robot for j in
                                                                         config.joins]}
    entries: list[dict[str, Any]] = []
    try:
        entries += [n for n in read_json(out_dir / "nodes.json")["nodes"] if isinstance(n, dict)]
    except (OSError, ValueError, KeyError, TypeError):
        pass
    for path in sorted((out_dir / "nodes").glob("*.json")):
        try:
            entries.append(read_json(path))
        except (OSError, ValueError):
            continue
    for n in entries:
        rid = n.get("robot")
        if isinstance(rid, str) and rid not in kinds and n.get("arena") and n.get("algo"):
            kinds[rid] = (str(n["arena"]), str(n["algo"]))
    return kinds


def write_summary(r: Results) -> Path:
    """``summary.md``: first whether the federation ran and what ran
    (:func:`~.what_ran.what_ran_lines`), then what came out."""
    c = r.config
    lines = [f"# {c.name}", "", c.default_title(), ""] + what_ran_lines(r) + [
             "", "## The run", "",
             f"- wall time: {r.wall_time_s:.1f} s",
             f"- mode: {c.mode.value}, real-time factor: {c.rtf or 'none (flat out)'}",
             f"- seed: {c.seed}; iterations {c.iterations}, respite {c.respite}, "
             f"rounds planned {c.rounds}"]
    made_by = read_provenance(r.output_dir)
    if made_by is not None:
        lines.append(f"- produced by {describe(made_by)} (provenance.json)")
    lines.append("")
    metrics_path = r.output_dir / "metrics.csv"
    curves = read_metrics(metrics_path) if metrics_path.is_file() else {}
    lines += ["| robot | arena | algo | iterations | final sum of Q (tables/) | cumulative reward "
              "| collisions |", "|---|---|---|---|---|---|---|"]
    kinds = robot_kinds(r.output_dir, c)
    kept = set(r.from_checkpoint or ())
    for rid, cur in curves.items():
        if len(cur) == 0:
            continue
        arena, algo = kinds.get(rid, ("?", "?"))
        last = cur[-1]
        final = table_sum(r.output_dir, rid)
        q = "no table saved" if final is None else f"{final:.2f}" + (
            " (sum of parameters, params/)" if params_path(r.output_dir, rid).is_file()
            else "") + (" (last checkpoint)" if rid in kept else "")
        lines.append(f"| {rid} | {arena} | {algo} | "
                     f"{int(last['iteration'])} | {q} | "
                     f"{last['cumulative_reward']:.1f} | {int(last['collisions'])} |")
    lines.append("")
    evals = last_evaluations(r.output_dir)
    for rid, e in evals.items():
        lines.append(f"- {rid}: last greedy evaluation (iteration {e['iteration']}, "
                     f"{e['steps']} steps): {e['collisions_per_1000']:.1f} collisions per 1,000 "
                     f"steps, progress {e['progress']:.3f}, coverage {e['coverage']:.3f}")
    if evals:
        lines.append("")
    failed = [row for row in r.rounds if row.get("error")]
    redone = [row for row in failed if row.get("failed_method")]
    partial = [row for row in r.rounds if row.get("skipped") and not row.get("error")]
    n_rounds = len(r.rounds)
    durations = sorted(float(row["duration_ms"]) for row in r.rounds
                       if row.get("duration_ms") not in (None, ""))
    median = (f"{durations[len(durations) // 2]:.1f} ms" if durations else
              "no round completed")
    grid = (" (a grid federation: a function learner's grid view holds the aggregate only "
            "within its distillation residual, so rounds that write one count as unequal)"
            if c.federation == GRID else "")
    rebuilt = sum(1 for row in r.rounds if row.get("reconstructed"))
    unverified = count_unverified(r.rounds)
    also = (f" ({unverified} more not verifiable: a visited robot's share record is missing, "
            f"e.g. lost with its host; the records there agree)" if unverified else "")
    lines += [f"- agent rounds logged: {n_rounds - rebuilt}"
              + (f" (and {rebuilt} only in the robots' shares, rebuilt)" if rebuilt else "")
              + f"; rounds after which every visited robot held "
              f"the same table: {r.equal_rounds}/{n_rounds}{also}{grid}; rounds that skipped "
              f"robots: "
              f"{len(partial)}; rounds whose method FAILED: {len(failed)} ({len(redone)} done "
              f"again with a fallback method, every table written; {len(failed) - len(redone)} "
              f"aborted, no table written)",
              f"- median round time: {median}",
              f"- methods used: "
              f"{', '.join(sorted({row['method'] for row in r.rounds} - {''})) or '-'}"
              + (f" (and failed: {', '.join(sorted({row['failed_method'] for row in redone}))})"
                 if redone else ""),
              f"- agents finished: {r.agents_finished}"]
    for row in failed[:10]:
        then = (f"; done again with {row['method']}" if row.get("failed_method") else
                "; aborted")
        lines.append(f"  - FAILED: {row['agent']} round {row['round']} "
                     f"({row.get('failed_method') or row['method']}): {row['error'][:300]}{then}")
    for row in partial[:10]:
        lines.append(f"  - skipped robots: {row['agent']} round {row['round']}: {row['skipped']}")
    warnings = node_warnings(r.output_dir)
    if warnings:
        lines.append(f"- {len(warnings)} warning(s) in logs/ (agent and nodes), first ones:")
        lines += [f"  - `{w[:200]}`" for w in warnings[:5]]
    for agent, problems in (r.log_problems or {}).items():
        if problems:
            lines.append(f"- {agent}: {len(problems)} problem(s) in its log, first ones:")
            lines += [f"  - `{p[:200]}`" for p in problems[:5]]
    if r.gathered:
        n = sum(len(v) for v in r.gathered.values())
        lines.append(f"- result files gathered over the platform from {len(r.gathered)} "
                     f"remote robot(s): {n}")
    if r.crashed:
        lines.append(f"- CRASHED robots (exit codes): {r.crashed}")
    for rid, why in (r.failed_joins or {}).items():
        lines.append(f"- join of {rid} FAILED (the robot did not start; not a fault of the "
                     f"federation): {why[:300]}")
    for problem in r.record_problems or []:
        lines.append(f"- RECORDS UNREADABLE: {problem}")
    for rid, problem in (r.table_problems or {}).items():
        lines.append(f"- TORN TABLE {rid}: {problem}")
    if r.faults is not None:
        fault_lines = r.faults.lines()
        verdict = "complete" if r.complete else "INCOMPLETE"
        lines += ["", f"## Faults: federation {verdict}", ""] + (fault_lines or ["- none"])
    if r.history is not None:
        lines += ["", f"## History: {'ok' if r.history.ok else 'VIOLATED'}", "",
                  r.history.text(shown=10)]
    elif r.faults is not None and r.faults.history:
        lines += ["", "## History: NOT CHECKED", "", r.faults.history[0]]
    if r.collected is not None:
        lines += ["", "## Collected after the driver stopped (dfrl collect)", ""]
        lines += [f"- {line}" for line in r.collected]
    if r.interrupted:
        lines.append(f"- INTERRUPTED ({r.interrupted}): partial results, robots stopped by "
                     "the launcher" + (f"; tables of {', '.join(sorted(kept))} kept from their "
                                       "last checkpoints" if kept else ""))
    plots = ", ".join(p.name for p in r.plots) if r.plots else "none"
    if r.plot_error:
        plots += f" ({r.plot_error})"
    lines += ["", "Plots: " + plots, ""]
    path = r.output_dir / "summary.md"
    path.write_text("\n".join(lines), encoding="utf-8")
    return path
