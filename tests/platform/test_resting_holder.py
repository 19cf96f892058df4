"""The dFRL agent has a holder at every instant, resting included (issue 20).

Each stop is its own ``swipl`` process (a platform node serving one in-memory robot with a table
of its own, ``memory_robots.pl``) on a fixed loopback port, so that it can be restarted there.
Faults are real: ``kill -9`` of the node the agent works or rests on. The round log (JSON lines)
is the record checked; each robot's table is asked from its process at the end.

The control runs the same fault with the flag ``dfrl_resting_holder`` false on every node (no
heartbeat, no adopted holder: the behaviour before), where an agent at its first stop after the
launch has no holder and dies with it.
"""

from __future__ import annotations

import signal
import time
from collections import Counter
from pathlib import Path

import pytest

from dfrl.platform_pl import PLATFORM_DIR

from .conftest import SWIPL, Proc
from .tour import Tour
from .wire_client import request

pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")

HERE = Path(__file__).parent
TOKEN = 7
SLACK_S = 1.5  # scheduling on a shared 2-core machine, a probe, the round's own time

NODE = f"""
:- use_module({str(PLATFORM_DIR / "tartarus.pl")!r}).
:- use_module({str(PLATFORM_DIR / "dfrl_agent" / "dfrl_agent.pl")!r}).
:- use_module({str(HERE / "memory_robots.pl")!r}).
main :-
    current_prolog_flag(argv, Argv),
    append(_, [PortA, Robot, V0A, DelayA, LeaseA, ReplyA, Legacy, Store], Argv), !,
    atom_number(PortA, Port), atom_number(V0A, V0), atom_number(DelayA, Delay),
    atom_number(LeaseA, Lease), atom_number(ReplyA, Reply),
    (   Legacy == legacy
    ->  set_prolog_flag(dfrl_resting_holder, false),
        set_prolog_flag(dfrl_replace_stale, false)
    ;   true
    ),
    V1 is V0 + 1.0,
    memory_robots_start([Robot-[V0, V1]]),
    memory_robot_delay(Robot, Delay),
    (   Store == none -> StoreOpts = [] ; StoreOpts = [store(Store)] ),
    node_start(localhost:Port, _, [token({TOKEN}), lease_s(Lease), connect_timeout(1),
                                   reply_timeout(Reply), default(true)|StoreOpts]),
    format("LISTENING ~w~n", [Port]), flush_output,
    (   getenv("DFRL_DBG", _)          % the platform's debug topics, to look into a failure
    ->  forall(member(T, [agent, move, lease, custody]), debug(dfrl(T)))
    ;   true
    ),
    serve_stdin(Robot).

serve_stdin(Robot) :-
    read_line_to_string(user_input, Line),
    (   Line == end_of_file
    ->  true
    ;   Line == "table"
    ->  memory_robot_table(Robot, T),
        format("TABLE ~w ~q~n", [Robot, T]), flush_output,
        serve_stdin(Robot)
    ;   split_string(Line, " ", "", ["delay", D]),
        number_string(S, D)
    ->  memory_robot_delay(Robot, S),
        format("DELAY ~w~n", [S]), flush_output,
        serve_stdin(Robot)
    ;   serve_stdin(Robot)
    ).
"""

CONSOLE = f"""
:- use_module({str(PLATFORM_DIR / "tartarus.pl")!r}).
:- use_module({str(PLATFORM_DIR / "dfrl_agent" / "dfrl_agent.pl")!r}).
main :-
    current_prolog_flag(argv, Argv),
    append(_, [PlanFile], Argv), !,
    read_file_to_terms(PlanFile, [plan(Stops, Rounds, Rest, Log, Options)], []),
    node_start(localhost:0, N, [token({TOKEN}), connect_timeout(1), reply_timeout(2)]),
    dfrl_create(N, fx, plan(Stops, Rounds, Rest, Log, 30), [tokens([{TOKEN}])|Options]),
    Stops = [stop(H, P, _)|_],
    move_agent(fx, (H, P)),
    format("LAUNCHED~n"), flush_output.
"""


class Stops(Tour):
    """Stop processes r0..r(n-1) on fixed ports, r_i's table [i, i+1]; a console launches ``fx``.

    Parameters
    ----------
    delays : list of float
        Seconds each robot's table read waits (a slow robot keeps the agent on its node).
    lease_s, reply_s : float
        Node options ``lease_s`` and ``reply_timeout`` of every stop.
    legacy : bool
        The flags ``dfrl_resting_holder`` and ``dfrl_replace_stale`` false on every stop.
    store : bool
        Every stop keeps its custody in a store (``store(Dir)``), kept across a restart.
    """

    def __init__(
        self,
        tmp_path: Path,
        procs: list[Proc],
        delays: list[float],
        *,
        lease_s: float = 1.5,
        reply_s: float = 8.0,
        legacy: bool = False,
        store: bool = False,
    ) -> None:
        super().__init__(tmp_path, procs, len(delays), TOKEN)
        self.store = store
        (tmp_path / "node.pl").write_text(NODE)
        (tmp_path / "console.pl").write_text(CONSOLE)
        self.delays, self.lease_s, self.reply_s, self.legacy = delays, lease_s, reply_s, legacy
        self.nodes: list[Proc] = [self.spawn(i) for i in range(len(delays))]  # in parallel
        for p in self.nodes:
            p.wait_for("LISTENING")

    def spawn(self, i: int) -> Proc:
        p = Proc(
            [
                SWIPL,
                "-q",
                "-g",
                "main",
                str(self.tmp / "node.pl"),
                str(self.ports[i]),
                f"r{i}",
                f"{float(i)}",
                str(self.delays[i]),
                str(self.lease_s),
                str(self.reply_s),
                "legacy" if self.legacy else "new",
                str(self.tmp / f"store{i}") if self.store else "none",
            ]
        )
        self.procs.append(p)
        return p

    def start(self, i: int) -> Proc:
        p = self.spawn(i)
        p.wait_for("LISTENING")
        return p

    def launch(self, rounds: int, rest: float, options: str = "[]") -> None:
        self.launch_plan(
            f"plan([{self.stops_term()}], {rounds}, {rest}, {str(self.log)!r}, {options})"
        )

    def table(self, i: int) -> list[float]:
        """Robot r_i's table, asked from its process."""
        node = self.nodes[i]
        seen = len(node.lines)
        assert node.popen.stdin is not None
        node.popen.stdin.write("table\n")
        node.popen.stdin.flush()
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline:
            for line in node.lines[seen:]:
                if line.startswith(f"TABLE r{i} "):
                    return [float(x) for x in line.split(" ", 2)[2].strip("[]").split(",")]
            time.sleep(0.02)
        raise AssertionError(f"r{i} did not print its table:\n{node.output()}")

    def kill(self, i: int) -> float:
        """kill -9 stop i; return the time (time.time()) of the kill."""
        t = time.time()
        self.nodes[i].popen.send_signal(signal.SIGKILL)
        self.nodes[i].popen.wait(timeout=5)
        return t


def rounds_once(stops: Stops, rounds: int) -> list[dict]:
    """Every planned round logged exactly once, the tour finished: no round lost or doubled."""
    rs = stops.events("round")
    counts = Counter(r["round"] for r in rs)
    assert counts == Counter(range(1, rounds + 1)), counts
    assert len(stops.events("finished")) == 1
    assert stops.events("aborted") == []
    return sorted(rs, key=lambda r: r["round"])


def report(name: str, value: float) -> None:
    print(f"MEASURED {name} {value:.2f}")


def test_first_stop_killed_in_round_one(tmp_path: Path, procs: list[Proc]) -> None:
    # Prepare: four stops, r0 slow: the agent works on its first stop, where the launch left it
    # (it came from the console, no stop: before, it had no holder there).
    lease = 1.5
    stops = Stops(tmp_path, procs, [2.0, 0.0, 0.0, 0.0], lease_s=lease)
    stops.launch(rounds=3, rest=0.2)
    stops.wait(lambda: stops.has_agent(0, "running"), 15, "the agent running on r0")
    time.sleep(0.3)
    # Execute: kill -9 its node mid-round 1.
    killed = stops.kill(0)
    stops.wait(lambda: stops.events("finished"), 40, "the end of the tour")
    # Assert: the adopted holder (r1) resurrected it within one lease (+ slack) of the kill;
    # every round once, r0 skipped; the tables of the robots visited are equal.
    [res] = stops.events("resurrected")
    assert (res["round"], res["epoch"], res["from"]) == (1, 2, stops.address(1)), res
    assert res["dead"] == stops.address(0)
    report("first-stop resurrection after kill (s)", res["time"] - killed)
    assert res["time"] - killed < lease + SLACK_S, res["time"] - killed
    for r in rounds_once(stops, 3):
        assert r["visited"] == ["r1", "r2", "r3"], r
        assert [s["robot"] for s in r["skipped"]] == ["r0"], r
    tables = [stops.table(i) for i in (1, 2, 3)]
    assert tables[0] == tables[1] == tables[2] == [2.0, 3.0], tables
    assert not any(stops.has_agent(i) for i in (1, 2, 3))


def test_first_stop_killed_in_round_one_control(tmp_path: Path, procs: list[Proc]) -> None:
    # Control: the same fault with the behaviour before (flag dfrl_resting_holder false): the
    # agent at its first stop has no holder, so it dies with it: no round, ever.
    lease = 1.5
    stops = Stops(tmp_path, procs, [2.0, 0.0, 0.0, 0.0], lease_s=lease, legacy=True)
    stops.launch(rounds=3, rest=0.2)
    stops.wait(lambda: stops.has_agent(0, "running"), 15, "the agent running on r0")
    time.sleep(0.3)
    stops.kill(0)
    time.sleep(lease + SLACK_S + 1.0)  # longer than the resurrection takes above
    assert stops.events("resurrected") == [] and stops.events("round") == []
    assert not any(stops.has_agent(i) for i in (1, 2, 3))


@pytest.mark.parametrize(
    "restart", [pytest.param(False, marks=pytest.mark.slow), True], ids=["no-restart", "restart"]
)
def test_resting_host_killed(tmp_path: Path, procs: list[Proc], restart: bool) -> None:
    # Prepare: five stops; the agent rests 0.8 s at its first stop between rounds.
    lease = 1.5
    stops = Stops(tmp_path, procs, [0.0] * 5, lease_s=lease)
    stops.launch(rounds=3, rest=0.8)
    stops.wait(lambda: stops.events("round"), 20, "round 1")
    # Execute: kill -9 the node it rests on; (restart it on its port 2 s later).
    killed = stops.kill(0)
    if restart:
        time.sleep(2.0)
        stops.nodes[0] = stops.start(0)
    stops.wait(lambda: stops.events("finished"), 60, "the end of the tour")
    # Assert: resurrected by its holder (the stop it came back from) within one lease + slack
    # of the kill, round 2 starts from there at once: no round lost, none logged twice.
    [res] = stops.events("resurrected")
    assert (res["round"], res["epoch"], res["from"]) == (2, 2, stops.address(1)), res
    rounds = rounds_once(stops, 3)
    stall = rounds[1]["start"] - killed
    report(
        f"resting-host kill ({'restart' if restart else 'no restart'}): "
        "next round start after kill (s)",
        stall,
    )
    assert stall < lease + SLACK_S, stall
    assert rounds[1]["skipped"] and rounds[1]["skipped"][0]["robot"] == "r0"
    assert all(r["epoch"] == 2 for r in rounds[1:])
    if restart:
        # the restarted stop is visited again (a new process: its table is its own again);
        # the last round's tables are equal everywhere
        assert rounds[-1]["visited"] == ["r0", "r1", "r2", "r3", "r4"], rounds[-1]
        tables = [stops.table(i) for i in range(5)]
    else:
        assert all("r0" not in r["visited"] for r in rounds[1:])
        tables = [stops.table(i) for i in range(1, 5)]
    assert all(t == tables[0] for t in tables), tables
    time.sleep(0.3)
    assert sum(stops.has_agent(i) for i in range(1 if not restart else 0, 5)) == 0


@pytest.mark.slow
def test_resting_host_restarted_with_its_store(tmp_path: Path, procs: list[Proc]) -> None:
    # Prepare: four stops that keep their custody on disk; the agent rests 0.8 s at r0.
    lease = 1.5
    stops = Stops(tmp_path, procs, [0.0] * 4, lease_s=lease, store=True)
    stops.launch(rounds=4, rest=0.8)
    stops.wait(lambda: stops.events("round"), 20, "round 1")
    # Execute: kill -9 the node it rests on; once it is resurrected elsewhere, restart that node
    # with its store: it recovers the old copy (epoch 1, running) and starts it again.
    stops.kill(0)
    stops.wait(lambda: stops.events("resurrected"), 20, "the resurrection")
    stops.nodes[0] = stops.start(0)
    stops.wait(lambda: stops.events("finished"), 60, "the end of the tour")
    # Assert: the recovered copy asked its holder first, learnt of epoch 2 and retired at once
    # (superseded, in the round it would have started); never two agents logging a round.
    [res] = stops.events("resurrected")
    [sup] = stops.events("superseded")
    assert (sup["epoch"], sup["by"]) == (1, 2), sup
    rounds = rounds_once(stops, 4)
    assert all(r["epoch"] == 2 for r in rounds[1:])
    assert rounds[-1]["visited"] == ["r0", "r1", "r2", "r3"], rounds[-1]
    tables = [stops.table(i) for i in range(4)]
    assert all(t == tables[0] for t in tables), tables
    time.sleep(0.5)
    assert not any(stops.has_agent(i) for i in range(4))


def test_hold_request_checks_what_it_stores(tmp_path: Path, procs: list[Proc]) -> None:
    # A stop asked to hold a checkpoint stores a record it would install unchecked if it
    # resurrected it: the record's code passes the sandbox check as an arrival's does, and the
    # resume point may carry no packed term (nothing a peer sends is deserialised).
    stops = Stops(tmp_path, procs, [0.0])
    custody = "(dfrl_custody_of(fx,custody(1,1,'localhost:1')):-true)"
    resume = "resume(_{acc:none,index:0},0,round_done(0,false))"

    def hold(handler_body: str, resume_term: str = resume) -> str:
        record = (
            f"agent(fx,dfrl_tour,mobile,[],[],[dfrl_custody_of/2],"
            f"[{custody},(dfrl_tour(_,_,_):-{handler_body})],[])"
        )
        return request(
            stops.ports[0],
            f"dfrl_custody(hold(fx,1,1,'localhost:1','localhost:2',{record},{resume_term}))",
            token=str(TOKEN),
        )

    unsafe = hold("shell(ls)")
    assert "refused(" in unsafe and "shell" in unsafe, unsafe
    packed = hold("true", 'resume(_{acc:packed("x"),index:0},0,round_done(0,false))')
    assert "refused(hold)" in packed, packed
    assert "ok(held)" in hold("true")  # control: a well-formed, safe record is held
