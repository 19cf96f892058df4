"""The faults of ``dfrl bench faults`` (issue 20), one small function each, with what each
must show (:class:`Expectation`).

A case's ``act`` runs once the driver has started: it waits for a few rounds, does its fault,
waits for the end of the run (and, for the killed driver, runs ``dfrl collect``) and returns
:class:`Acted`: when the fault struck, which robot it struck, and which exit status and which
results folder carry the run's verdict. Cases are listed cheapest first in :data:`CASES`.

Issue 33's cases cut, for 30 s or 90 s, one of the three places the resting agent depends on
(its plan: :data:`DEFAULT_ROUNDS` rounds unless ``--rounds`` says otherwise):

- ``cut_holder_S``: the host holding the resting agent's lease. In a sync run the agent rests
  between rounds on the round's first stop; its holder is the stop it came from
  (platform_pl/README.md "The dFRL agent: faults"; dfrl_lease.pl "Depart"): in a chain the
  last stop of the backward pass before the first, the round's second stop; in a tree the
  root never moves, and its holder is the stop it adopted (request ``hold``, the stops after
  it first), again the second stop. The case locates it at fault time from the round just
  logged (:func:`holder_of`: ``visited[1]`` of the driver's last ``round`` record, visited in
  itinerary order), right after that round is logged, while the agent rests.
- ``cut_agent_host_S``: the host the agent rests on (``visited[0]`` of that record).
- ``cut_driver_S``: the driver's host (its link to the bridge); the robots and the agent go on.

``kill_driver_collect`` is ``kill_driver`` on hosts that share no disk (every run of this
benchmark: :mod:`.faults_federation`), reporting what ``dfrl collect`` found.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from dfrl.experiments.tools.bench.faults_federation import Federation, Plan, wait_until

#: the longest a fault may keep the federation from completing a round: one lease (the
#: platform node's ``lease_s``, 10 s: a dead host's agent is resurrected within it; an
#: unreachable stop is skipped after ``skip_after_s``, 4 s), plus 5 s for a round and the
#: slack of a loaded 2-core machine
RECOVERY_BOUND_S = 15.0
#: the round after which every fault strikes (the federation has found its pace)
FAULT_AFTER_ROUND = 3
#: rounds of issue 33's cases unless ``--rounds`` says otherwise
DEFAULT_ROUNDS = 30
#: the agent's ``skip_after`` (dfrl_create/4's default): the longest one move is tried
SKIP_AFTER_S = 4.0

#: an aggregation method whose step fails at run time (written where ``dfrl inject`` reads it)
FAILING_METHOD = """\
/*  An aggregation method whose step fails at run time (dfrl bench faults). */
:- multifile dfrl_aggregation:aggregate_init/3, dfrl_aggregation:aggregate_step/4,
             dfrl_aggregation:aggregate_final/3.

dfrl_aggregation:aggregate_init(failing, qtable(_, V), V).
dfrl_aggregation:aggregate_step(failing, _, _, _) :- fail.
dfrl_aggregation:aggregate_final(failing, A, A).
"""


@dataclass(frozen=True)
class Expectation:
    """What a fault run must show to pass (besides identical tables in every completed round
    and a truthful verdict and exit status, which every case requires)."""

    max_rounds_lost: int = 0  #: planned rounds not completed
    recovery_bound_s: float = RECOVERY_BOUND_S  #: fault -> next completed round
    stall_bound_s: float = RECOVERY_BOUND_S  #: the longest gap between completed rounds
    victim_misses: bool = True  #: the struck robot missed at least one round
    rejoin: bool = False  #: ... and was visited again before the end
    method_failed: bool = False  #: at least one round's method failed (and was reported)
    #: the robots' shares pass the history checker (no doubled write, no stale epoch...)
    history_clean: bool = True
    #: the longest gap between rounds written on the robots stays below the agent's skip
    #: time plus one normal round (a fault the rounds need not wait for: the driver's)
    gap_within_skip: bool = False
    #: the run's verdict must be INCOMPLETE and its exit status non-zero (a robot was cut)
    incomplete: bool = False

    def text(self) -> str:
        parts = [
            f"at most {self.max_rounds_lost} planned round(s) not completed",
            f"a completed round within {self.recovery_bound_s:g} s of the fault",
            f"no gap over {self.stall_bound_s:g} s between two completed rounds",
            "identical tables in every completed round",
            "summary verdict and exit status truthful (complete only if every robot "
            "took part in every round; absent robots and failed methods named)",
        ]
        if self.victim_misses:
            parts.append("the struck robot misses rounds")
        if self.rejoin:
            parts.append("and is visited again before the end")
        if self.method_failed:
            parts.append(
                "the failing method's round reported and the next rounds complete (fallback)"
            )
        if self.history_clean:
            parts.append("the robots' shares pass the history checker")
        if self.gap_within_skip:
            parts.append(
                f"no gap between rounds written on the robots over skip time "
                f"({SKIP_AFTER_S:g} s) plus one normal round"
            )
        if self.incomplete:
            parts.append("verdict INCOMPLETE and a non-zero exit status")
        return "; ".join(parts)


@dataclass
class Acted:
    """What a case did: the fault's time (time.time()), the robot it struck (None: the
    driver), and the exit status and folder whose verdict counts."""

    t_fault: float
    victim: str | None
    exit_status: int
    results: Path
    notes: list[str] = field(default_factory=list)
    #: figures of the case's own, copied into the run's record
    extra: dict[str, object] = field(default_factory=dict)


@dataclass(frozen=True)
class Case:
    name: str
    what: str
    expect: Expectation
    plan: Callable[[int], Plan]  #: robot hosts -> the experiment
    act: Callable[[Federation], Acted]


def _rounds_plan(rounds: int) -> Callable[[int], Plan]:
    """A plan of ``rounds`` sync rounds (respite 100 at 4 x real time: ~1.7 s a round here),
    its ``timeout_s`` three times its expected length plus a minute."""
    return lambda hosts: Plan(
        hosts=hosts, iterations=100 * rounds, timeout_s=60.0 + 3 * 2.5 * rounds
    )


def _ended(fed: Federation, t_fault: float, victim: str | None) -> Acted:
    return Acted(t_fault, victim, fed.wait_driver(), fed.out)


def restart_robot(fed: Federation) -> Acted:
    """kill -9 the last robot's host after round 3; start it again 2 s later."""
    victim = fed.robots[-1]
    fed.wait_rounds(FAULT_AFTER_ROUND)
    t = fed.kill_host(victim)
    time.sleep(2.0)
    fed.restart(victim)
    return _ended(fed, t, victim)


def kill_mid_hop(fed: Federation) -> Acted:
    """kill -9 the next-to-last robot's host as the agent leaves the last stop for it in
    round 4's backward pass (right after the last robot applied that round's table)."""
    victim, before = fed.robots[-2], fed.robots[-1]
    fed.wait_rounds(FAULT_AFTER_ROUND)
    seen = fed.shares(before)
    wait_until(
        lambda: fed.shares(before) > seen, 60, f"{before}'s share of the next round", poll_s=0.003
    )
    t = fed.kill_host(victim)
    note = (
        f"killed {1000 * (t - _last_share_time(fed, before)):.0f} ms after {before} "
        f"applied round {seen + 1}'s table; {victim} had applied {fed.shares(victim)} "
        "tables"
    )
    acted = _ended(fed, t, victim)
    acted.notes.append(note)
    return acted


def _last_share_time(fed: Federation, robot: str) -> float:
    p = fed.shares_file(robot)
    lines = [ln for ln in p.read_text().splitlines() if ln] if p else []
    return float(lines[-1].split(",")[3]) if len(lines) > 1 else float("nan")


def failing_method(fed: Federation) -> Acted:
    """``dfrl inject`` a method whose step fails, after round 2 (the fault's time: when the
    agent acknowledged it)."""
    fed.wait_rounds(2)
    program = fed.work / "driver" / "failing_method.pl"
    program.write_text(FAILING_METHOD, encoding="utf-8")
    t = time.time()
    fed.mark("dfrl inject of failing_method.pl (method failing)", t)
    done = fed.dfrl_on_driver(
        "inject",
        "out",
        "--program",
        str(program),
        "--method",
        "failing",
        "--wait",
        "60",
        timeout_s=120,
    )
    acked = time.time()
    fed.mark(
        f"dfrl inject exited {done.returncode}: {(done.stdout + done.stderr).strip()[:200]}", acked
    )
    # the fault strikes in the round the agent applied the method in, which starts once the
    # injection is acknowledged
    return _ended(fed, acked if done.returncode == 0 else t, None)


def kill_driver(fed: Federation) -> Acted:
    """kill -9 the driver's host after round 3; ``dfrl collect out`` once the robots ended."""
    fed.wait_rounds(FAULT_AFTER_ROUND)
    t = fed.kill_driver()
    done = fed.dfrl_on_driver(
        "collect", "out", "--wait", str(int(fed.plan.timeout_s)), timeout_s=fed.plan.timeout_s + 90
    )
    fed.mark(f"dfrl collect exited {done.returncode}")
    acted = Acted(t, None, done.returncode, fed.out)
    acted.extra["collect_exit"] = done.returncode
    if done.returncode != 0:
        acted.notes.append(f"dfrl collect: {done.stderr.strip()[-500:]}")
    return acted


def holder_of(visited: tuple[str, ...]) -> str:
    """The robot whose host holds the resting agent's lease, from the round just logged
    (``visited`` in itinerary order): the stop it came from, the round's second stop (see
    the module doc; a one-stop round has no holder: ValueError)."""
    if len(visited) < 2:
        raise ValueError(f"a round that visited {list(visited)} leaves the agent no holder")
    return visited[1]


def _cut_for(seconds: float, which: str) -> Callable[[Federation], Acted]:
    """Cut, right after round 3 is logged (the agent resting), ``which`` host's link for
    ``seconds``: ``holder`` (the lease holder's), ``agent`` (the resting agent's) or
    ``driver``; then mend it and wait for the end of the run."""

    def cut(fed: Federation) -> Acted:
        last = fed.wait_rounds(FAULT_AFTER_ROUND)
        visited = tuple(last.visited)
        if which == "driver":
            t = fed.cut_host("driver")
            victim = None
        else:
            victim = holder_of(visited) if which == "holder" else visited[0]
            t = fed.cut(victim)
        located = (
            f"round {last.round} (epoch {last.epoch}) visited {' '.join(visited)}: the "
            f"agent rests on {visited[0]}, its lease holder is {holder_of(visited)}"
        )
        time.sleep(max(0.0, t + seconds - time.time()))
        if victim is None:  # which == "driver"
            fed.mend_host("driver")
        else:
            fed.mend(victim)
        acted = _ended(fed, t, victim)
        acted.notes.append(located)
        acted.extra.update(rests_on=visited[0], holder=holder_of(visited), cut_s=seconds)
        return acted

    cut.__doc__ = f"cut the {which} host's link after round 3 for {seconds:g} s, then mend it"
    return cut


def kill_resting(fed: Federation) -> Acted:
    """kill -9 the host the agent rests on between rounds (the round's first stop), right
    after round 3 is logged; start it again 10 s later."""
    last = fed.wait_rounds(FAULT_AFTER_ROUND)
    victim = last.visited[0]
    t = fed.kill_host(victim)
    time.sleep(max(0.0, t + 10.0 - time.time()))
    fed.restart(victim)
    return _ended(fed, t, victim)


def _cut(seconds: float) -> Callable[[Federation], Acted]:
    def cut(fed: Federation) -> Acted:
        victim = fed.robots[len(fed.robots) // 2]
        fed.wait_rounds(FAULT_AFTER_ROUND)
        t = fed.cut(victim)
        time.sleep(max(0.0, t + seconds - time.time()))
        fed.mend(victim)
        return _ended(fed, t, victim)

    cut.__doc__ = f"cut a middle host's link after round 3 for {seconds:g} s, then mend it"
    return cut


def _default_rounds() -> Callable[[int], Plan]:
    return _rounds_plan(DEFAULT_ROUNDS)


def _cut_plan(seconds: float) -> Callable[[int], Plan]:
    # enough rounds that the run outlasts the cut by ~8 rounds even at ~1.5 s a round
    return _rounds_plan(FAULT_AFTER_ROUND + int(seconds / 1.5) + 8)


CASES: dict[str, Case] = {
    c.name: c
    for c in (
        Case(
            "restart_robot",
            "kill -9 a robot host after round 3, restart it 2 s later",
            Expectation(rejoin=True),
            _rounds_plan(15),
            restart_robot,
        ),
        Case(
            "kill_mid_hop",
            "kill -9 a robot host while the agent hops to it (backward pass)",
            Expectation(),
            _rounds_plan(12),
            kill_mid_hop,
        ),
        Case(
            "failing_method",
            "inject an aggregation method whose step fails (dfrl inject)",
            Expectation(victim_misses=False, method_failed=True),
            _rounds_plan(12),
            failing_method,
        ),
        Case(
            "kill_driver",
            "kill -9 the driver's host after round 3, then dfrl collect",
            Expectation(victim_misses=False),
            _rounds_plan(12),
            kill_driver,
        ),
        Case(
            "kill_resting",
            "kill -9 the host the agent rests on, restart it 10 s later",
            Expectation(rejoin=True),
            _rounds_plan(25),
            kill_resting,
        ),
        Case(
            "cut_30s",
            "cut a robot host's link for 30 s (Lab.cut, Lab.mend)",
            Expectation(rejoin=True),
            _cut_plan(30),
            _cut(30),
        ),
        Case(
            "cut_90s",
            "cut a robot host's link for 90 s (Lab.cut, Lab.mend)",
            Expectation(rejoin=True),
            _cut_plan(90),
            _cut(90),
        ),
        Case(
            "kill_driver_collect",
            "kill -9 the driver's host after round 3, then dfrl collect "
            "on hosts that share no disk",
            Expectation(victim_misses=False),
            _default_rounds(),
            kill_driver,
        ),
        *(
            Case(
                f"cut_{which_name}_{s}",
                f"cut the {what} host's link for {s} s after round 3",
                expect,
                _default_rounds(),
                _cut_for(s, which),
            )
            for s in (30, 90)
            for which_name, which, what, expect in (
                (
                    "holder",
                    "holder",
                    "resting agent's lease holder's",
                    Expectation(incomplete=True),
                ),
                ("agent_host", "agent", "resting agent's", Expectation(incomplete=True)),
                (
                    "driver",
                    "driver",
                    "driver's",
                    Expectation(victim_misses=False, gap_within_skip=True),
                ),
            )
        ),
    )
}
