"""The first lines of ``summary.md``: whether the federation ran, and what ran.

:func:`what_ran_lines` gives, in this order, lines that claim no more than happened:

1. **Status**: ``complete`` (every planned round of every agent, every robot in each, up to
   what the config tolerates), ``INCOMPLETE`` (with the rounds each agent missed, the robots
   that missed rounds or were lost, and why), or ``NEVER STARTED`` (no agent was launched:
   e.g. a robot host refused the run's token; why, as the launcher recorded it).
2. **Itinerary**: per agent, the robots it went over (the launched plan from ``nodes.json``,
   else the config's, marked as never launched), chain or tree.
3. **What the agent carried** and how it aggregated it: Q-tables (element-wise mean,
   maximum, or visit-weighted mean), parameter vectors averaged by FedAvg with each robot's
   weight (``fedavg_weights.csv``), or, in a grid federation, tables on the state grid that
   the function learners absorb by distillation, with its residual per robot and round
   (``distillation.csv``).
4. **Learners**: per robot, alpha, gamma and the epsilon schedule (and a function learner's
   own settings), read from the robots' configs.

Pure functions of a :class:`~.summary.Results` and the files of its folder; they write
nothing.
"""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from dfrl.experiments.driver.config import GRID, ExperimentConfig
from dfrl.experiments.driver.results.carried import Distilled, Weight
from dfrl.experiments.driver.results.files import read_json

if TYPE_CHECKING:
    from dfrl.experiments.driver.results.summary import Results

__all__ = ["launched_agents", "planned_agents", "run_status", "what_ran_lines"]

#: What each built-in method does to the tables it folds.
METHOD_WORDS: dict[str, str] = {
    "average": "the element-wise mean of the robots' tables",
    "max": "the element-wise maximum of the robots' tables",
    "visit_average": "the mean of the robots' tables weighted, entry by entry, by their visit "
                     "counts",
}
#: Rows of the distillation table shown in the summary (every row is in distillation.csv).
SHOWN_ROUNDS = 12


def planned_agents(config: ExperimentConfig) -> list[tuple[str, str, tuple[str, ...]]]:
    """``(agent, label, robots)`` per agent the config plans, in launch order: one per
    algorithm (``fed_<algo>``), or ``fed_grid`` over every robot; robots in config order
    (robots that join later are added to it when they join)."""
    out = []
    for label, algos in config.agent_groups():
        robots = tuple(s.id for s in config.robots if s.algo in algos)
        if robots:
            out.append((f"fed_{label}", label, robots))
    return out


def launched_agents(out: Path) -> dict[str, dict[str, Any]]:
    """agent -> its entry in ``nodes.json`` (the agents the launcher launched; none when the
    file is missing or unreadable)."""
    try:
        agents = read_json(Path(out) / "nodes.json").get("agents", [])
    except (OSError, ValueError, AttributeError):
        return {}
    return {a["name"]: a for a in agents if isinstance(a, dict) and isinstance(a.get("name"), str)}


def _rounds_done(r: "Results") -> dict[str, set[int]]:
    done: dict[str, set[int]] = {}
    for row in r.rounds:
        if not row.get("error") or row.get("failed_method"):
            done.setdefault(str(row["agent"]), set()).add(int(row["round"]))
    return done


def _shown(numbers: list[int]) -> str:
    return ", ".join(map(str, numbers[:20])) + (" ..." if len(numbers) > 20 else "")


def run_status(r: "Results") -> tuple[str, list[str]]:
    """The run's status word (``complete``, ``INCOMPLETE``, ``NEVER STARTED``) and the reasons,
    one line each (see the module doc)."""
    c = r.config
    launched = launched_agents(r.output_dir)
    planned = planned_agents(c)
    if not r.rounds and not launched:
        why = r.start_error or (f"interrupted ({r.interrupted})" if r.interrupted else
                                "no agent was launched")
        return "NEVER STARTED", [f"no agent was launched and no round ran: {why}"]
    done = _rounds_done(r)
    faults = r.faults
    reasons: list[str] = []
    counts: list[str] = []          # agent: done of planned rounds
    names = list(dict.fromkeys([a for a, _, _ in planned] + list(launched) + list(done)))
    for agent in names:
        missing = faults.missing_rounds.get(agent, []) if faults is not None else []
        if agent not in launched and not done.get(agent):
            reasons.append(f"{agent} was never launched: none of its {c.rounds} rounds ran")
        else:
            n = len(done.get(agent, ()))
            counts.append(f"{agent}: {n} of {n + len(missing)} planned rounds")
            reasons.append(f"{counts[-1]} done"
                           + (f"; missing: {_shown(missing)}" if missing else ""))
    if faults is not None:
        reasons += [f"LOST {rid}: {why}" for rid, why in faults.lost.items()]
        reasons += [f"{rid} {what}" for rid, what in faults.missed.items()]
        for agent, errors in faults.method_errors.items():
            if errors:
                reasons.append(f"{agent}: the method failed in {len(errors)} round(s)")
        if faults.history:
            reasons.append(f"the history of table writes broke its rules "
                           f"({len(faults.history)} violation(s))")
        reasons += faults.other[:5]
    reasons += [f"{rid} crashed (exit code {code})" for rid, code in (r.crashed or {}).items()
                if not (faults and rid in faults.lost)]
    reasons += [f"{a} did not log its end" for a, end in r.agents_finished.items()
                if end is None and a in launched and not r.interrupted]
    if r.interrupted:
        reasons.append(f"interrupted ({r.interrupted})")
    if r.complete and r.ok:
        rounds = ", ".join(counts)
        tolerated = " (faults within what the config tolerates: see Faults)" \
            if faults is not None and faults.lines() else ""
        return "complete", [f"every planned round ran, every robot took part in every round "
                            f"of its agent ({rounds}){tolerated}"]
    return "INCOMPLETE", reasons or ["the run did not end cleanly (see below)"]


def _itinerary_lines(r: "Results") -> list[str]:
    c = r.config
    launched = launched_agents(r.output_dir)
    out = []
    for agent, label, robots in planned_agents(c):
        info = launched.get(agent)
        if info is not None:
            robots = tuple(str(s.get("robot")) for s in info.get("itinerary", []))
        kind = (info or {}).get("kind", c.itinerary)
        fanout = (info or {}).get("fanout", c.fanout)
        if kind == "tree":
            shape = (f"tree rooted at {robots[0] if robots else '?'}, fan-out {fanout}, over "
                     f"{', '.join(robots)} (clones read and write their robots at once)")
        else:
            shape = (f"chain {' -> '.join(robots)} and back (reads on the way out, writes on "
                     f"the way back)")
        joined = sorted({rid for row in r.rounds if row.get("agent") == agent
                         for rid in str(row.get("visited", "")).split()} - set(robots))
        also = f"; joined later: {', '.join(joined)}" if joined else ""
        never = "" if info is not None else " (planned; never launched)"
        out.append(f"- itinerary of {agent}: {shape}, {c.rounds} rounds planned{also}{never}")
    return out


def _methods(r: "Results", agent: str, default: str) -> list[str]:
    used = list(dict.fromkeys(str(row["method"]) for row in r.rounds
                              if row.get("agent") == agent and row.get("method")))
    return used or [default]


def _method_text(methods: list[str]) -> str:
    return "; then ".join(f"{m} ({METHOD_WORDS[m]})" if m in METHOD_WORDS else
                          f"{m} (a method injected with dfrl inject)" for m in methods)


def _weights_line(agent: str, weights: list[Weight]) -> str:
    mine = [w for w in weights if w.agent == agent]
    if not mine:
        return "weights: none recorded (no round wrote parameters)"
    last = max(w.round for w in mine)
    cells = ", ".join(f"{w.robot} {w.samples} samples"
                      + ("" if w.weight is None else f" ({w.weight:.3f})")
                      for w in mine if w.round == last)
    return f"weights in round {last}: {cells}; every round's in fedavg_weights.csv"


def _carried_lines(r: "Results") -> list[str]:
    c = r.config
    from dfrl.robots.learners import learner_kind

    out = []
    for agent, label, robots in planned_agents(c):
        methods = _methods(r, agent, c.method_for(label))
        if label == GRID:
            function = [s.id for s in c.robots if learner_kind(s.algo) == "function"]
            views = (f"; {', '.join(function)} (function learners) take part through grid "
                     f"views: their Q-function at the centres of the grid's cells, and absorb "
                     f"the aggregate by distillation, within the residual below"
                     if function else "")
            out.append(f"- {agent} carried Q-tables on the discretised state grid, aggregated "
                       f"by {_method_text(methods)}{views}")
        elif learner_kind(label) == "function":
            fedavg = " or ".join("FedAvg (the mean weighted by each robot's samples, the "
                                 "transitions it had learnt from when read)" if m == "average"
                                 else f"{m} (a method injected with dfrl inject)"
                                 for m in methods)
            out.append(f"- {agent} carried parameter vectors ({label}), averaged by {fedavg}; "
                       + _weights_line(agent, r.weights or []))
        else:
            out.append(f"- {agent} carried Q-tables ({label}), aggregated by "
                       f"{_method_text(methods)}")
    return out


def _distillation_lines(rows: list[Distilled]) -> list[str]:
    """The residual of every distilled write: one row per (agent, round), one column per
    robot, ``RMS before -> after``."""
    if not rows:
        return []
    robots = sorted({d.robot for d in rows})
    keys = sorted({(d.agent, d.round) for d in rows})
    cell = {(d.agent, d.round, d.robot): d for d in rows}
    lines = ["", "Distillation residual (RMS of Q at the grid's points minus the written "
             "table, before -> after; every row in distillation.csv):", "",
             "| agent | round | " + " | ".join(robots) + " |",
             "|---|---|" + "---|" * len(robots)]
    shown = keys if len(keys) <= SHOWN_ROUNDS else \
        keys[:SHOWN_ROUNDS // 2] + keys[-(SHOWN_ROUNDS // 2):]
    for agent, n in shown:
        cells = []
        for rid in robots:
            d = cell.get((agent, n, rid))
            cells.append("-" if d is None else f"{d.rms_before:.4f} -> {d.rms_after:.4f}")
        lines.append(f"| {agent} | {n} | " + " | ".join(cells) + " |")
        if len(keys) > SHOWN_ROUNDS and (agent, n) == keys[SHOWN_ROUNDS // 2 - 1]:
            lines.append(f"| ... | {len(keys) - SHOWN_ROUNDS} rounds more |"
                         + " |" * len(robots))
    worst = max(rows, key=lambda d: d.rms_after)
    lines += ["", f"Largest residual after distillation: {worst.rms_after:.4f} RMS "
              f"({worst.robot}, {worst.agent} round {worst.round}; largest entry "
              f"{worst.max_after:.4f})"]
    return lines


def _learner_text(cfg: Any, algo: str, plugins: dict[str, Any]) -> str:
    """One robot's learner settings in words (``cfg``: its TrainerConfig; ``plugins``: the
    config's plug-in learners)."""
    lp = cfg.learner
    eps = lp.epsilon
    kind = getattr(eps.kind, "value", eps.kind)
    schedule = (f"epsilon {eps.start:g} (constant)" if kind == "constant" else
                f"epsilon {kind} {eps.start:g} -> {eps.end:g} over {eps.decay_steps:,} updates")
    if algo == "linear":
        own = (f"tile coding {cfg.linear.tilings} tilings x {cfg.linear.tiles} tiles, "
               f"alpha {cfg.linear.alpha:g}")
    elif algo == "dqn":
        d = cfg.dqn
        own = (f"network {'x'.join(map(str, d.hidden))}, Adam lr {d.lr:g}, batch "
               f"{d.batch_size}, replay {d.buffer_size:,}, learning starts {d.learning_starts}, "
               f"target copied every {d.target_update} steps")
    elif algo in plugins:
        spec = plugins[algo]
        spec = spec if isinstance(spec, dict) else {"class": spec}
        options = ", ".join(f"{k} {v}" for k, v in spec.get("options", {}).items())
        own = f"plug-in {spec.get('class')}" + (f" with {options}" if options else "") \
            + f", initial Q {lp.initial_q:g}"
    else:
        own = f"alpha {lp.alpha:g}, initial Q {lp.initial_q:g}"
    return f"{own}, gamma {lp.gamma:g}, {schedule}"


def _learner_lines(r: "Results") -> list[str]:
    from dfrl.robots.trainer_config import TrainerConfig

    c = r.config
    specs = list(c.robots) + [j.robot for j in c.joins]
    texts: dict[str, list[str]] = {}
    for spec in specs:
        trainer = dict(c.trainer)
        try:        # the robot's own config, as the launcher wrote it, when there is one
            node = read_json(r.output_dir / "nodes" / f"{spec.id}.json")
            trainer = dict(node.get("trainer", trainer))
        except (OSError, ValueError, AttributeError):
            pass
        try:
            base = TrainerConfig().to_dict()
            base.update(trainer)
            base.update(algo=spec.algo)
            text = _learner_text(TrainerConfig.from_dict(base), spec.algo, c.learners)
        except (ValueError, TypeError, KeyError) as exc:
            text = f"settings unreadable: {exc}"
        texts.setdefault(f"({spec.algo}): {text}", []).append(spec.id)
    return [f"- {', '.join(ids)} {text}" for text, ids in texts.items()]


def what_ran_lines(r: "Results") -> list[str]:
    """The summary's first section (see the module doc), as Markdown lines."""
    word, reasons = run_status(r)
    lines = [f"**Status: {word}**", ""]
    lines += [f"- {why}" for why in reasons]
    lines += ["", "## What ran", ""]
    lines += _itinerary_lines(r)
    lines += _carried_lines(r)
    lines += _distillation_lines(r.distilled or [])
    lines += ["", "Learners (alpha, gamma, exploration; from the robots' configs):", ""]
    lines += _learner_lines(r)
    return lines
