"""Work done inside C (issue 32): a peer holding the node's token sends agents whose one call
into C would build a 400 MB atom or string (format ``~*c``, atomic_list_concat/2, doubling
atom_concat/3) or a 1.1 Gbit integer (``7^400000000``), or that fill a memory stream write by
write (``with_output_to/2``). SWI-Prolog 9.0.4 handles no signal inside C, so the CPU and stack
bounds cannot stop them once started: guest_limits.pl checks the sizes before the call (a
memory stream's before each write, with what it holds) and node_memory.pl holds the process's RSS
to its baseline plus agent_memory_budget. Real
processes; RSS peak from /proc (VmHWM). Each attack has a control: the same code with small
sizes runs on the same node and prints the right result.
"""

from __future__ import annotations

import re
import time
from pathlib import Path

import pytest

from tests.platform.conftest import SWIPL, Proc
from tests.security.bounds_helpers import MIB, attacker, start_victim, status

pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")

# Each handler takes its size from a fact, so that the sizes are known at run time only (the
# check at install would refuse a literal 400000000): size(guid, Kind, N). The attacker sends the
# same handlers with big sizes (b*) and, as controls, small ones (c*).
AGENTS = """
:- dynamic fmt/3, alc/3, dbl/3, wot/3, pw/3, lit_fmt/3, lit_pow/3, size/3.
fmt(guid, _, main) :- size(guid, n, N), format(atom(A), "~*c", [N, 0'x]),
    atom_length(A, L), format("FMT ~w~n", [L]), flush_output.
alc(guid, _, main) :- size(guid, n, N), M is N // 100, format(atom(B), "~*c", [M, 0'y]),
    length(Xs, 100), maplist(=(B), Xs), atomic_list_concat(Xs, A),
    atom_length(A, L), format("ALC ~w~n", [L]), flush_output.
dbl(guid, _, main) :- size(guid, d, D), numlist(1, D, Ks),
    foldl([_, A0, A1]>>atom_concat(A0, A0, A1), Ks, x, A), atom_length(A, L),
    format("DBL ~w~n", [L]), flush_output.
wot(guid, _, main) :- size(guid, n, N), M is N // 100, format(atom(B), "~*c", [M, 0'z]),
    with_output_to(string(S), forall(between(1, 100, _), write(B))),
    string_length(S, L), format("WOT ~w~n", [L]), flush_output.
pw(guid, _, main) :- size(guid, p, P), X is 7^P, Y is X mod 1000,
    format("POW ~w~n", [Y]), flush_output.
lit_fmt(guid, _, main) :- format(atom(A), "~*c", [400000000, 0'x]), atom_length(A, _).
lit_pow(guid, _, main) :- X is 7^400000000, X > 0.
with_size(Name, Handler, Sizes, Port) :-
    retractall(size(_, _, _)), forall(member(K-V, Sizes), assertz(size(guid, K, V))),
    create_mobile_agent(Name, Handler, [5]),
    add_payload(Name, [size/3]),
    report(move_agent(Name, (localhost, Port))),
    format("SENT ~w~n", [Name]), flush_output.
"""

BIG = "[n-400000000, d-29, p-400000000]"
SMALL = "[n-100000, d-10, p-100]"


def test_c_level_bombs_within_budget(tmp_path: Path, procs: list[Proc]) -> None:
    budget = 512 * MIB
    victim, port = start_victim(
        procs, tmp_path, f"agent_cpu_limit(30), agent_memory_budget({budget})"
    )
    pid = victim.popen.pid
    time.sleep(0.3)
    base = status(pid, "VmRSS")
    bombs = ["b_fmt-fmt", "b_alc-alc", "b_dbl-dbl", "b_wot-wot", "b_pow-pw"]
    sends = "".join(
        f"with_size({n.split('-')[0]}, {n.split('-')[1]}, {BIG}, {port}), " for n in bombs
    )
    awaits = "".join(f"await_report({n.split('-')[0]}, 40), " for n in bombs)
    a = attacker(
        procs,
        tmp_path,
        AGENTS,
        f"""
        send(l_fmt, lit_fmt, {port}), send(l_pow, lit_pow, {port}),
        get_time(T0), {sends}
        send(g1, good, {port}),
        {awaits}
        get_time(T1), D is T1 - T0, format("ALL STOPPED after ~3f s~n", [D]),
    """,
    )
    a.wait_for("SENT b_pow", 60)
    t_sent = time.monotonic()
    victim.wait_for("GOOD at", 5)  # an ordinary agent, sent amid the bombs: within 5 s
    served = time.monotonic() - t_sent
    a.wait_for("DONE", 120)
    out = a.output()
    hwm = status(pid, "VmHWM")
    # refused at install, naming the culprit
    refusals = re.findall(r"RESULT (.*)", out)
    assert sum("Refused mobile code" in r and "400000000" in r for r in refusals) == 2, out
    assert "dfrl_guest_text_limit" in out and "dfrl_guest_integer_bits" in out, out
    # stopped at run time by a bound, the sender told
    kinds = dict(re.findall(r"REPORT (b_\w+) (\w+)\(", out))
    assert set(kinds) == {"b_fmt", "b_alc", "b_dbl", "b_wot", "b_pow"}, out
    # the memory stream filled write by write: its writes checked together (a sink), before each
    # write, not by the RSS monitor's tick, which a busy machine delays
    assert kinds["b_fmt"] == kinds["b_alc"] == kinds["b_dbl"] == kinds["b_wot"] == "text_size", (
        kinds
    )
    assert kinds["b_pow"] == "integer_size", kinds
    print(
        f"C-level bombs: {a.wait_for('ALL STOPPED')}, stopped by {kinds}; RSS before "
        f"{base // 1024} MiB, peak +{(hwm - base) // 1024} MiB; good agent served in {served:.2f} s"
    )
    # the stated bound (README "Bounds on agents"): baseline + agent_memory_budget + 256 MiB
    # (the growth of one monitor tick, and the atoms and buffers in flight of 8 running calls)
    assert (hwm - base) * 1024 < budget + 256 * MIB, (base, hwm)
    for word in ("FMT", "ALC", "DBL", "WOT", "POW"):
        assert f"{word} " not in victim.output(), victim.output()


def test_c_level_controls_run(tmp_path: Path, procs: list[Proc]) -> None:
    victim, port = start_victim(procs, tmp_path)
    names = ["c_fmt-fmt", "c_alc-alc", "c_dbl-dbl", "c_wot-wot", "c_pow-pw"]
    sends = "".join(
        f"with_size({n.split('-')[0]}, {n.split('-')[1]}, {SMALL}, {port}), " for n in names
    )
    a = attacker(procs, tmp_path, AGENTS, sends)
    a.wait_for("DONE", 60)
    try:
        for line in (
            "FMT 100000",
            "ALC 100000",
            "DBL 1024",
            "WOT 100000",
            f"POW {pow(7, 100, 1000)}",
        ):
            victim.wait_for(line, 20)
    except AssertionError:
        raise AssertionError(a.output() + victim.output())
    assert "stopped and removed" not in victim.output(), victim.output()
