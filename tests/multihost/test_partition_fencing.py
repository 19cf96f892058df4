"""One agent, one writer, under a partition (issue 33): five stops, each a ``swipl`` node in a
network namespace of its own, and a console in a sixth; the agent walks a chain and rests at
its first stop (s0) between rounds, its lease held by the stop it came from (s1).

- Cut the lease holder (s1) for several leases: the holder, alone, must not resurrect the agent
  (before issue 33 it did: a second copy with epoch 2 and rounds run twice); the agent finds
  another holder and goes on without s1.
- Cut the agent's host (s0) while the agent rests there: the majority resurrects it with the
  next epoch; the copy cut off writes nothing once its lease ran out and retires when the cut
  heals; exactly one copy is left.

Each robot keeps the history of its table writes (round, agent, epoch, digest) in the columns
of a ``shares_<robot>.csv``; the history checker (``dfrl check-history``) judges them: no robot
written twice in a round, no write of a superseded epoch, one table per round. Control: the
same cut of s1 with the holder's quorum off is shown to break that (``dfrl_quorum`` false).
"""

from __future__ import annotations

import json
import subprocess
import time
from pathlib import Path

import pytest

from dfrl.experiments.driver.results.history import check_history
from dfrl.experiments.tools.netns import Lab, unavailable

from ..platform.conftest import PLATFORM_DIR, SWIPL

WHY = unavailable() or (None if SWIPL else "swipl not installed")
pytestmark = [pytest.mark.skipif(WHY is not None, reason=WHY or ""), pytest.mark.slow]

HERE = Path(__file__).resolve().parent
MEMORY_ROBOTS = HERE.parent / "platform" / "memory_robots.pl"
TOKEN = 463709187335281729054263357812893156702
PORT = 7300
LEASE_S = 2.0
STOPS = 5

NODE = f"""
:- use_module({str(PLATFORM_DIR / "tartarus.pl")!r}).
:- use_module({str(PLATFORM_DIR / "dfrl_agent" / "dfrl_agent.pl")!r}).
:- use_module({str(MEMORY_ROBOTS)!r}).
main :-
    current_prolog_flag(argv, Argv),
    append(_, [Host, PortA, Robot, V0A, LeaseA, History, Quorum], Argv), !,
    atom_number(PortA, Port), atom_number(V0A, V0), atom_number(LeaseA, Lease),
    (   Quorum == off -> set_prolog_flag(dfrl_quorum, false) ; true ),
    V1 is V0 + 1.0,
    memory_robots_start([Robot-[V0, V1]]),
    memory_robot_history(Robot, History),
    node_start(Host:Port, _, [token({TOKEN}), lease_s(Lease), connect_timeout(1),
                              reply_timeout(2), default(true)]),
    format("LISTENING ~w~n", [Port]), flush_output,
    serve_stdin.

serve_stdin :-
    read_line_to_string(user_input, Line),
    (   Line == end_of_file
    ->  true
    ;   Line == "agents"
    ->  current_node(N),
        findall(A-S, agent_property(N, A, status(S)), L),
        format("AGENTS ~q~n", [L]), flush_output,
        serve_stdin
    ;   split_string(Line, " ", "", ["delay", D]),
        number_string(S, D)
    ->  forall(memory_robot_table(R, _), memory_robot_delay(R, S)),
        format("DELAY ~w~n", [S]), flush_output,
        serve_stdin
    ;   serve_stdin
    ).
"""

CONSOLE = f"""
:- use_module({str(PLATFORM_DIR / "tartarus.pl")!r}).
:- use_module({str(PLATFORM_DIR / "dfrl_agent" / "dfrl_agent.pl")!r}).
main :-
    current_prolog_flag(argv, Argv),
    append(_, [Host, PlanFile], Argv), !,
    read_file_to_terms(PlanFile, [plan(Stops, Rounds, Rest, Log, Options)], []),
    node_start(Host:0, N, [token({TOKEN}), connect_timeout(1), reply_timeout(2)]),
    dfrl_create(N, fx, plan(Stops, Rounds, Rest, Log, 30), [tokens([{TOKEN}])|Options]),
    Stops = [stop(H, P, _)|_],
    move_agent(fx, (H, P)),
    format("LAUNCHED~n"), flush_output.
"""


class Federation:
    """The five stops and the console in a lab; the round log and the robots' histories in
    ``tmp``."""

    def __init__(self, lab: Lab, tmp: Path, quorum: bool = True) -> None:
        self.lab, self.tmp = lab, tmp
        (tmp / "node.pl").write_text(NODE)
        (tmp / "console.pl").write_text(CONSOLE)
        self.log = tmp / "rounds.jsonl"
        self.nodes: list[subprocess.Popen] = []
        for i in range(STOPS):
            host = lab[f"s{i}"]
            p = host.popen(
                [
                    SWIPL,
                    "-q",
                    "-g",
                    "main",
                    str(tmp / "node.pl"),
                    host.address,
                    str(PORT),
                    f"r{i}",
                    f"{float(i)}",
                    str(LEASE_S),
                    str(tmp / f"shares_r{i}.csv"),
                    "on" if quorum else "off",
                ],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=open(tmp / f"s{i}.err", "w"),
                text=True,
                bufsize=1,
            )
            self.nodes.append(p)
        for p in self.nodes:
            assert p.stdout is not None
            assert p.stdout.readline().startswith("LISTENING"), "a stop did not start"

    def launch(self, rounds: int, rest: float, itinerary: str = "chain") -> None:
        stops = ",".join(f"stop('{self.lab[f's{i}'].address}',{PORT},r{i})" for i in range(STOPS))
        plan = self.tmp / "plan.txt"
        kind = "" if itinerary == "chain" else ", itinerary(tree(2))"
        plan.write_text(
            f"plan([{stops}], {rounds}, {rest}, {str(self.log)!r}, [skip_after(1.0){kind}]).\n"
        )
        drv = self.lab["drv"]
        done = drv.run(
            [
                SWIPL,
                "-q",
                "-g",
                "main",
                "-t",
                "halt",
                str(self.tmp / "console.pl"),
                drv.address,
                str(plan),
            ],
            timeout=60,
            capture_output=True,
            text=True,
        )
        assert "LAUNCHED" in done.stdout, done.stdout + done.stderr

    def events(self, kind: str | None = None) -> list[dict]:
        if not self.log.exists():
            return []
        out = [json.loads(x) for x in self.log.read_text().splitlines() if x.strip()]
        return [e for e in out if kind is None or e["event"] == kind]

    def wait(self, cond, timeout: float, what: str) -> None:  # noqa: ANN001
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if cond():
                return
            time.sleep(0.05)
        raise AssertionError(
            f"timed out waiting for {what}; log:\n"
            + "\n".join(json.dumps(e) for e in self.events())
        )

    def agents(self, i: int) -> str:
        """What stop i lists (``AGENTS [Name-Status, ...]``)."""
        p = self.nodes[i]
        assert p.stdin is not None and p.stdout is not None
        p.stdin.write("agents\n")
        p.stdin.flush()
        return p.stdout.readline().strip()

    def command(self, i: int, line: str) -> str:
        p = self.nodes[i]
        assert p.stdin is not None and p.stdout is not None
        p.stdin.write(line + "\n")
        p.stdin.flush()
        return p.stdout.readline().strip()

    def stderr(self) -> str:
        return "\n".join(
            f"--- s{i}\n" + (self.tmp / f"s{i}.err").read_text()[-3000:] for i in range(STOPS)
        )


def _tour_with_a_cut(
    lab: Lab, tmp: Path, host: str, itinerary: str = "chain", quorum: bool = True
) -> Federation:
    """Launch a 16-round tour, cut ``host`` for four leases after round 4, wait for the end."""
    fed = Federation(lab, tmp, quorum)
    fed.launch(rounds=16, rest=0.6, itinerary=itinerary)
    _cut_after_a_round(fed, host, 4 * LEASE_S)
    fed.wait(lambda: fed.events("finished"), 120, "the end of the tour")
    return fed


def _cut_after_a_round(fed: Federation, host: str, seconds: float) -> None:
    """Wait for round 4 to be logged (the agent then rests at s0, held by s1), cut ``host``
    for ``seconds``, mend it."""
    fed.wait(lambda: len(fed.events("round")) >= 4, 60, "four rounds")
    time.sleep(0.1)
    fed.lab.cut(host)
    time.sleep(seconds)
    fed.lab.mend(host)


def _judge(fed: Federation) -> None:
    verdict = check_history(fed.tmp)
    assert verdict.ok, verdict.text() + "\n" + fed.stderr()
    assert len(fed.events("finished")) == 1, fed.events()
    for i in range(STOPS):
        assert "fx" not in fed.agents(i), (i, fed.agents(i))


ITINERARIES = ["chain", "tree"]


@pytest.mark.parametrize("itinerary", ITINERARIES)
def test_cut_holder_does_not_resurrect(tmp_path: Path, itinerary: str) -> None:
    with Lab([*(f"s{i}" for i in range(STOPS)), "drv"]) as lab:
        fed = _tour_with_a_cut(lab, tmp_path, "s1", itinerary)
        time.sleep(LEASE_S)  # a late copy would show itself now
        assert fed.events("resurrected") == [], fed.events("resurrected")
        _judge(fed)
        rounds = fed.events("round")
        assert sorted(r["round"] for r in rounds) == list(range(1, 17)), rounds
        cut_rounds = [r for r in rounds if "r1" not in r["visited"]]
        assert cut_rounds, "the cut of s1 did not cost s1 a round"


@pytest.mark.parametrize("itinerary", ITINERARIES)
def test_cut_agent_host_leaves_one_writer(tmp_path: Path, itinerary: str) -> None:
    with Lab([*(f"s{i}" for i in range(STOPS)), "drv"]) as lab:
        fed = _tour_with_a_cut(lab, tmp_path, "s0", itinerary)
        fed.wait(lambda: fed.events("superseded"), 20, "the cut copy to retire")
        [res] = fed.events("resurrected")
        assert res["epoch"] == 2 and res["dead"].startswith(lab["s0"].address), res
        [sup] = fed.events("superseded")
        assert (sup["epoch"], sup["by"]) == (1, 2), sup
        _judge(fed)
        by_round: dict[int, list[int]] = {}
        for r in fed.events("round"):
            by_round.setdefault(r["round"], []).append(r["epoch"])
        assert all(len(v) == 1 for v in by_round.values()), by_round


def test_cut_holder_without_quorum_is_split_brain(tmp_path: Path) -> None:
    # Control: the same cut with the holder's quorum off (flag dfrl_quorum false, the
    # behaviour before issue 33): the holder cut off resurrects a second copy, and the
    # history checker sees what it did.
    with Lab([*(f"s{i}" for i in range(STOPS)), "drv"]) as lab:
        fed = _tour_with_a_cut(lab, tmp_path, "s1", quorum=False)
        time.sleep(2 * LEASE_S)
        assert [r["from"] for r in fed.events("resurrected")] == [f"{lab['s1'].address}:{PORT}"]
        verdict = check_history(fed.tmp)
        assert not verdict.ok, verdict.text()


def test_cut_mid_round_starts_a_new_round(tmp_path: Path) -> None:
    # The agent sits at s2 (its robot slow to read) in the forward pass when s2 is cut off:
    # its holder s1, with the majority, resurrects it into the next round (the copy at s2 might
    # still write r2 in this one); the copy cut off writes nothing once its lease ran out.
    with Lab([*(f"s{i}" for i in range(STOPS)), "drv"]) as lab:
        fed = Federation(lab, tmp_path)
        fed.launch(rounds=12, rest=0.6)
        fed.wait(lambda: len(fed.events("round")) >= 3, 60, "three rounds")
        assert fed.command(2, "delay 3.0").startswith("DELAY")
        fed.wait(lambda: "fx-running" in fed.agents(2), 30, "the agent reading r2")
        fed.lab.cut("s2")
        time.sleep(4 * LEASE_S)
        fed.lab.mend("s2")
        fed.command(2, "delay 0.0")
        fed.wait(lambda: fed.events("finished"), 120, "the end of the tour")
        fed.wait(lambda: fed.events("superseded"), 20, "the cut copy to retire")
        [res] = fed.events("resurrected")
        assert res["epoch"] == 2 and res["from"] == f"{lab['s1'].address}:{PORT}", res
        _judge(fed)
