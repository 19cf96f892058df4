"""What went wrong in a run, and whether the federation still completed.

:class:`Faults` collects, from the agents' logs and what the launcher saw: the stops each
agent skipped (and why), resurrections of an agent whose host died, rounds planned but never
logged, robots lost (a local process that crashed, a remote robot that failed or stopped
answering) and stalls (a robot that made no progress, or could not be reached, for a while
and then came back). :meth:`Faults.complete` is the verdict the run's exit status follows.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable

from dfrl.experiments.driver.config import ExperimentConfig
from dfrl.experiments.driver.results.agent_log import AgentLog, RoundRecord


@dataclass
class Faults:
    """Faults of one run (see the module doc); every list holds readable lines."""

    skips: list[str] = field(default_factory=list)
    resurrections: list[str] = field(default_factory=list)
    missing_rounds: dict[str, list[int]] = field(default_factory=dict)
    lost: dict[str, str] = field(default_factory=dict)
    stalls: list[str] = field(default_factory=list)
    other: list[str] = field(default_factory=list)
    #: agent -> "round N: error" for each round whose aggregation method failed
    method_errors: dict[str, list[str]] = field(default_factory=dict)
    #: robot -> "AGENT: rounds it was skipped in, and when it came back" (it took no part)
    missed: dict[str, str] = field(default_factory=dict)

    def complete(self, config: ExperimentConfig) -> bool:
        """Every agent logged its planned rounds and every robot took part in every round of
        its agent (none lost, none skipped), up to what the config tolerates
        (``tolerate_missing_rounds`` per agent, ``tolerate_lost_robots``: robots lost or
        skipped in some round, ``tolerate_method_errors`` per agent: rounds whose aggregation
        method failed), and nothing else (e.g. result files that could not be gathered) went
        wrong."""
        worst = max((len(v) for v in self.missing_rounds.values()), default=0)
        failed = max((len(v) for v in self.method_errors.values()), default=0)
        absent = set(self.lost) | set(self.missed)
        return (worst <= config.tolerate_missing_rounds
                and len(absent) <= config.tolerate_lost_robots and not self.other
                and failed <= config.tolerate_method_errors)

    def lines(self) -> list[str]:
        """The summary's fault section (empty when there was none)."""
        out = []
        for agent, rounds in self.missing_rounds.items():
            if rounds:
                shown = ", ".join(map(str, rounds[:20])) + (" ..." if len(rounds) > 20 else "")
                out.append(f"- MISSING rounds of {agent} ({len(rounds)}): {shown}")
        for agent, errors in self.method_errors.items():
            if errors:
                out.append(f"- METHOD FAILED in {len(errors)} round(s) of {agent}:")
                out += [f"  - {e}" for e in errors[:20]]
        for rid, why in self.lost.items():
            out.append(f"- LOST robot {rid}: {why}")
        for rid, what in self.missed.items():
            out.append(f"- MISSED rounds: {rid} {what}")
        for title, items in (("skipped stops", self.skips),
                             ("resurrections", self.resurrections),
                             ("stalls", self.stalls), ("other faults", self.other)):
            if items:
                out.append(f"- {title} ({len(items)}):")
                out += [f"  - {item}" for item in items[:50]]
                if len(items) > 50:
                    out.append(f"  - ... {len(items) - 50} more")
        return out


def planned_rounds(log: AgentLog, rounds: int) -> int:
    """Rounds the agent was to run: its budget, or fewer when a ``stop`` command ended it."""
    for c in log.controls:
        if c.status == "applied" and c.command == "stop":
            return min(rounds, c.round)
    return rounds


def assess(config: ExperimentConfig, logs: Iterable[tuple[AgentLog, int]],
           lost: dict[str, str], stalls: Iterable[str] = (),
           other: Iterable[str] = (), resumed: dict[str, list[int]] | None = None,
           finished: Iterable[str] = ()) -> Faults:
    """The faults of a run from its agents' logs (each with its round budget) and what the
    launcher recorded (``resumed``: robot -> the checkpoint iterations it was resumed at
    after its robot host restarted; ``finished``: robots that ran all their iterations, whose
    skips after their last visit are no missed rounds: they had ended)."""
    f = Faults(lost=dict(lost), stalls=list(stalls), other=list(other))
    for log, budget in logs:
        for rec in log.rounds:
            for s in rec.skipped:
                f.skips.append(f"{log.agent} round {rec.round}: {s.robot} skipped "
                               f"({' '.join(s.reason.split())})")
        for r in log.resurrections:
            f.resurrections.append(f"{log.agent} round {r.round}: resurrected at {r.source} "
                                   f"with epoch {r.epoch} ({r.dead} did not answer)")
        for x in log.superseded:
            f.resurrections.append(f"{log.agent} round {x.round}: a late copy (epoch {x.epoch}) "
                                   f"met epoch {x.by} and purged itself")
        for d in log.duplicates:
            f.resurrections.append(f"{log.agent} round {d.round}: also logged by the superseded "
                                   f"copy of epoch {d.epoch} (not counted)")
        f.method_errors[log.agent] = [method_error_text(rec) for rec in log.rounds if rec.error]
        _missed(f, log, resumed or {}, set(finished))
        done = {rec.round for rec in log.rounds}
        f.missing_rounds[log.agent] = [n for n in range(1, planned_rounds(log, budget) + 1)
                                       if n not in done]
    return f


def method_error_text(rec: RoundRecord) -> str:
    """A round whose method failed, in words: which, why, and what became of the round."""
    error = " ".join(rec.error.split())
    if rec.failed_method:
        return (f"round {rec.round} ({rec.failed_method}): {error}; the round was done again "
                f"with {rec.method}, every table written")
    return f"round {rec.round} ({rec.method}): {error}; aborted, no table written"


def _missed(f: Faults, log: AgentLog, resumed: dict[str, list[int]],
            finished: set[str]) -> None:
    """The robots ``log``'s agent skipped, each with the rounds it missed and, per spell of
    absence, when it was lost and whether it came back (visited again; the k-th return of a
    robot resumed after a restart is its k-th resume)."""
    skipped: dict[str, list[int]] = {}
    for rec in log.rounds:
        for s in rec.skipped:
            skipped.setdefault(s.robot, []).append(rec.round)
    for rid, rounds in skipped.items():
        last_visit = max((rec.round for rec in log.rounds if rid in rec.visited), default=0)
        if rid in finished:             # skipped once it had ended: nothing missed
            rounds = [r for r in rounds if r < last_visit]
        if not rounds:
            continue
        spells = []
        checkpoints = list(resumed.get(rid, ()))
        for first in (r for r in rounds if r - 1 not in rounds):
            back = next((rec.round for rec in log.rounds
                         if rec.round > first and rid in rec.visited), None)
            how = ""
            if back and checkpoints:
                how = f" from its checkpoint at iteration {checkpoints.pop(0)}"
            spells.append(f"lost at round {first}, "
                          + (f"rejoined at round {back}{how}" if back else "never visited again"))
        shown = ", ".join(map(str, rounds[:20])) + (" ..." if len(rounds) > 20 else "")
        line = f"missed {len(rounds)} round(s) of {log.agent}: {shown} ({'; '.join(spells)})"
        f.missed[rid] = f"{f.missed[rid]}; {line}" if rid in f.missed else line
