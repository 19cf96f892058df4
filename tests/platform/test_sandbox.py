"""Mobile code from an authenticated peer, across real processes (issue 9).

A peer that proved the node's token tries to run shell, open a file and halt
the node through (i) an arriving agent, (ii) a post and (iii) load_program_text.
Each is refused, the sender sees why, nothing runs, the refused agent is still
at its source (idle, or running as before) and the node still serves.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from dfrl.platform_pl import PLATFORM_DIR

from .conftest import SWIPL, Proc, start_node

pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")


def attacker(procs: list[Proc], tmp_path: Path, body: str, port: int) -> Proc:
    """A console process with its own node and the victim's token."""
    pwned = tmp_path / "pwned"
    prog = f"""
    :- use_module({str(PLATFORM_DIR / "tartarus.pl")!r}).
    :- dynamic evil/3, opener/3, stopper/3, good/3, mover/3, sink/4.
    evil(guid, _, main) :- shell('touch {pwned}').
    opener(guid, _, main) :- open({str(pwned)!r}, write, S), close(S).
    stopper(guid, _, main) :- halt.
    good(guid, (_, P), main) :- format("GOOD at ~w~n", [P]), flush_output.
    mover(guid, _, main) :-
        catch(move_agent(guid, (localhost, {port})), E, true),
        message_to_text(E, T), format("MOVER ~w~n", [T]), flush_output.
    report(Goal) :-
        catch((Goal, T = ok), E, message_to_text(E, T)),
        format("RESULT ~w~n", [T]), flush_output.
    message_to_text(E, T) :-
        ( var(E) -> T = none ; message_to_codes(E, T) ).
    message_to_codes(E, T) :-
        '$messages':translate_message(E, L, []),
        with_output_to(string(T), print_message_lines(current_output, '', L)).
    main :- node_start(localhost:0, _, [token(5)]),
            {body}
            format("DONE~n"), flush_output.
    """
    path = tmp_path / f"attacker_{len(procs)}.pl"
    path.write_text(prog)
    proc = Proc([SWIPL, "-q", "-g", "main", "-t", "halt", str(path)])
    procs.append(proc)
    return proc


def test_arriving_agents_refused_and_kept_at_home(tmp_path: Path, procs: list[Proc]) -> None:
    node, port = start_node(procs, "--token", "5")
    a = attacker(
        procs,
        tmp_path,
        f"""
        forall(member(H, [evil, opener, stopper]),
               ( atom_concat(H, '_1', N),
                 create_mobile_agent(N, H, [5]),
                 report(move_agent(N, (localhost, {port}))) )),
        list_agents(L), format("HOME ~w~n", [L]),
        current_node(Here),
        forall(member(N, L), ( agent_property(Here, N, status(S)),
                               format("STATUS ~w ~w~n", [N, S]) )),
        create_mobile_agent(m1, mover, [5]),
        get_tartarus_details(Ip, Pt), execute_agent(m1, (Ip, Pt), mover),
        sleep(1), list_agents(L2), format("AFTER ~w~n", [L2]),
        create_mobile_agent(g1, good, [5]),
        report(move_agent(g1, (localhost, {port}))),
    """,
        port,
    )
    a.wait_for("DONE")
    out = a.output()
    results = [line for line in out.splitlines() if line.startswith("RESULT")]
    assert len(results) == 4, out
    for line, culprit in zip(results, ["shell(", "open(", "halt("]):
        assert "Refused mobile code" in line and culprit in line, out
    assert results[3] == "RESULT ok", out
    assert "HOME [evil_1,opener_1,stopper_1]" in out
    for name in ("evil_1", "opener_1", "stopper_1"):
        assert f"STATUS {name} idle" in out
    assert "MOVER" in out and "Refused mobile code" in a.wait_for("MOVER")
    assert "m1" in a.wait_for("AFTER")  # the running agent stayed
    node.wait_for("GOOD at")  # the node still serves
    assert not (tmp_path / "pwned").exists()


def test_posts_and_programs_refused(tmp_path: Path, procs: list[Proc]) -> None:
    node, port = start_node(procs, "--token", "5")
    pwned = tmp_path / "pwned"
    a = attacker(
        procs,
        tmp_path,
        f"""
        report(agent_post(localhost:{port}, platform, shell, x, ['touch {pwned}'])),
        report(agent_post(localhost:{port}, platform, halt, x, [])),
        report(load_program_text(localhost:{port}, evil,
               ":- initialization(shell('touch {pwned}')).", [])),
        report(load_program_text(localhost:{port}, evil2,
               "marker(1).\\nx :- open('{pwned}', write, _).", [])),
        report(load_program_text(localhost:{port}, evil3, ":- halt.", [])),
        report(load_program_text(localhost:{port}, good,
               ":- dynamic greet/3.\\ngreet(guid, (_, P), main) :- format(\\"GREET ~w~n\\", [P]), flush_output.", [])),
        create_mobile_agent(g2, good, [5]),
        report(move_agent(g2, (localhost, {port}))),
    """,
        port,
    )
    a.wait_for("DONE")
    out = a.output()
    results = [line for line in out.splitlines() if line.startswith("RESULT")]
    assert len(results) == 7, out
    assert "does not exist" in results[0] and "does not exist" in results[1], out
    for line in results[2:5]:
        assert "Refused mobile code" in line, out
    assert results[5] == "RESULT ok" and results[6] == "RESULT ok", out
    node.wait_for("GOOD at")
    assert not pwned.exists()
