"""What went wrong in a run, and whether the federation still completed.

:class:`Faults` collects, from the agents' logs, the robots' shares (the writes each
recorded) and what the launcher saw: the stops each agent skipped (and why), resurrections
of an agent whose host died, rounds planned but never done, robots lost (a local process
that crashed, a remote robot that failed or stopped answering), robots that missed rounds
(by the shares: absent from rounds the others were written in; a robot the log skipped but
whose share of the round is there missed nothing), robots that ended short of their
iterations, stalls (a robot that made no progress, or could not be reached, for a while and
then came back) and the history checker's violations (:mod:`.history`).
:meth:`Faults.complete` is the verdict the run's exit status follows.
"""
from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

from dfrl.experiments.driver.config import ExperimentConfig
from dfrl.experiments.driver.results.agent_log import AgentLog, RoundRecord
from dfrl.experiments.driver.results.rounds import Share, counted_writes


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
    #: robot -> "AGENT: rounds it missed, and when it came back" (it took no part)
    missed: dict[str, str] = field(default_factory=dict)
    #: robot -> "ended at iteration I of N": it ran fewer iterations than it was to (named;
    #: the verdict counts it through ``lost`` and ``missed``: a stop command or the end of
    #: the agents' rounds also ends robots early)
    short: dict[str, str] = field(default_factory=dict)
    #: agent -> rounds its log lacks that the robots' shares hold (rebuilt in rounds.csv)
    reconstructed: dict[str, list[int]] = field(default_factory=dict)
    #: the history checker's violations (or why it could not check): any makes the
    #: federation incomplete
    history: list[str] = field(default_factory=list)

    def complete(self, config: ExperimentConfig) -> bool:
        """Every agent logged its planned rounds and every robot took part in every round of
        its agent (none lost, none skipped), up to what the config tolerates
        (``tolerate_missing_rounds`` per agent, ``tolerate_lost_robots``: robots lost or
        skipped in some round, ``tolerate_method_errors`` per agent: rounds whose aggregation
        method failed), the history of the table writes kept its rules (:mod:`.history`), and
        nothing else (e.g. result files that could not be gathered) went wrong."""
        worst = max((len(v) for v in self.missing_rounds.values()), default=0)
        failed = max((len(v) for v in self.method_errors.values()), default=0)
        absent = set(self.lost) | set(self.missed)
        return (worst <= config.tolerate_missing_rounds
                and len(absent) <= config.tolerate_lost_robots and not self.other
                and failed <= config.tolerate_method_errors and not self.history)

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
        for rid, what in self.short.items():
            out.append(f"- ENDED SHORT: {rid} {what}")
        for agent, rounds in self.reconstructed.items():
            if rounds:
                shown = ", ".join(map(str, rounds[:20])) + (" ..." if len(rounds) > 20 else "")
                out.append(f"- NOT LOGGED rounds of {agent} ({len(rounds)}), rebuilt from the "
                           f"robots' shares in rounds.csv: {shown}")
        if self.history:
            out.append(f"- HISTORY VIOLATED ({len(self.history)}):")
            out += [f"  - {item}" for item in self.history[:50]]
            if len(self.history) > 50:
                out.append(f"  - ... {len(self.history) - 50} more")
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
           finished: Iterable[str] = (),
           shares: Mapping[str, Sequence[Share]] | None = None,
           short: Mapping[str, str] | None = None,
           history: Iterable[str] = ()) -> Faults:
    """The faults of a run from its agents' logs (each with its round budget), the robots'
    shares and what the launcher recorded.

    Parameters
    ----------
    config : ExperimentConfig
    logs : iterable of (AgentLog, int)
    lost : dict
        robot -> why it counts as lost.
    stalls, other : iterable of str
    resumed : dict, optional
        robot -> the checkpoint iterations it was resumed at after its robot host restarted.
    finished : iterable of str
        Robots that ran all their iterations: their absences after their last round are no
        missed rounds (they had ended).
    shares : mapping, optional
        robot -> its recorded writes (``shares_<robot>.csv``): a robot that recorded a write
        of a round missed nothing of it, whatever the log says; a robot absent from a round
        the others recorded missed it (:func:`absences`); a round only the shares hold was
        done (not missing), and is listed in ``reconstructed``.
    short : mapping, optional
        robot -> "ended at iteration I of N" (see :attr:`Faults.short`).
    history : iterable of str
        The history checker's violations, one line each.
    """
    f = Faults(lost=dict(lost), stalls=list(stalls), other=list(other),
               short=dict(short or {}), history=list(history))
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
        written = counted_writes(shares or {}, log.agent)
        _missed(f, log, resumed or {}, set(finished), written)
        logged = {rec.round for rec in log.rounds}
        f.reconstructed[log.agent] = sorted(set(written) - logged)
        done = logged | set(written)
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
            finished: set[str], written: Mapping[int, Mapping[str, Share]]) -> None:
    """The robots that missed rounds of ``log``'s agent, each with the rounds it missed and,
    per spell of absence, when it was lost and whether it came back (visited again or
    written again; the k-th return of a robot resumed after a restart is its k-th resume).
    A round is missed when the log skipped the robot and it recorded no write of the round,
    or when the shares show it absent from a round the others were written in
    (:func:`absences`)."""
    visited = {rec.round: rec.visited for rec in log.rounds}
    missed: dict[str, set[int]] = {}
    for rec in log.rounds:
        for s in rec.skipped:
            if s.robot not in written.get(rec.round, {}):
                missed.setdefault(s.robot, set()).add(rec.round)
    for rid, rounds in absences(written, visited, finished).items():
        missed.setdefault(rid, set()).update(rounds)
    took_part = {n: set(visited.get(n, ())) | set(written.get(n, {}))
                 for n in set(visited) | set(written)}
    for rid in sorted(missed):
        rounds = sorted(missed[rid])
        last_visit = max((n for n, rs in took_part.items() if rid in rs), default=0)
        if rid in finished:             # skipped once it had ended: nothing missed
            rounds = [r for r in rounds if r < last_visit]
        if not rounds:
            continue
        spells = []
        checkpoints = list(resumed.get(rid, ()))
        for first in (r for r in rounds if r - 1 not in rounds):
            back = min((n for n, rs in took_part.items() if n > first and rid in rs),
                       default=None)
            how = ""
            if back and checkpoints:
                how = f" from its checkpoint at iteration {checkpoints.pop(0)}"
            spells.append(f"lost at round {first}, "
                          + (f"rejoined at round {back}{how}" if back else "never visited again"))
        shown = ", ".join(map(str, rounds[:20])) + (" ..." if len(rounds) > 20 else "")
        line = f"missed {len(rounds)} round(s) of {log.agent}: {shown} ({'; '.join(spells)})"
        f.missed[rid] = f"{f.missed[rid]}; {line}" if rid in f.missed else line


def absences(written: Mapping[int, Mapping[str, Share]],
             visited: Mapping[int, Iterable[str]] | None = None,
             finished: Iterable[str] = ()) -> dict[str, list[int]]:
    """robot -> the rounds it missed by the shares: rounds of the agent that some robot
    recorded (``written``, from :func:`counted_writes`), after the robot's first recorded
    write of the agent, in which it recorded none.

    Not counted: a round the agent's log says it visited the robot in (``visited``: round ->
    robots; its share record is then missing, e.g. dropped when the robot resumed from an
    earlier checkpoint, which ``rounds.csv`` shows as ``missing``), and for a robot in
    ``finished`` (it ran all its iterations) the rounds after its last recorded write (it had
    ended). Rounds before a robot's first write are the log's to tell (a robot that joined
    later missed nothing of them).
    """
    members: dict[str, tuple[int, int]] = {}
    for n, robots in written.items():
        for robot in robots:
            lo, hi = members.get(robot, (n, n))
            members[robot] = (min(lo, n), max(hi, n))
    done = set(finished)
    seen = {n: set(robots) for n, robots in (visited or {}).items()}
    out: dict[str, list[int]] = {}
    for robot, (first, last) in sorted(members.items()):
        missed = [n for n in sorted(written) if n > first and robot not in written[n]
                  and robot not in seen.get(n, set())
                  and not (robot in done and n > last)]
        if missed:
            out[robot] = missed
    return out
