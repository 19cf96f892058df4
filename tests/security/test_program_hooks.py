"""Programs a token holder sends to a node (issue 32), across real processes.

A victim node in its own ``swipl`` (the dFRL agent loaded, as a robot's node has it) and an
attacker console with the victim's token, which sends programs with ``load_program_text/4``:

- every hook the Prolog system or a library calls by name, each in a program of its own, is
  refused, and the refusal names the hook (the program's marker fact never loads); control: an
  ordinary program loads;
- after the refused ``prolog_exception_hook/4`` program, a malformed frame from an
  unauthenticated peer is answered and the node does not spin;
- two programs defining the same names load side by side, each aggregation method calling its
  own helper (checked by an agent that runs both methods on the victim);
- a program whose initialization loops is stopped by the bounds (CPU; a sleeping loop by the
  wall clock), the attacker gets ``resource_error(program_initialization(..))``, and the node
  answers a ping and takes an ordinary agent afterwards, with no CPU left spinning.
"""

from __future__ import annotations

import socket
import time
from pathlib import Path

import pytest

from dfrl.platform_pl import PLATFORM_DIR
from tests.platform import hostile_node
from tests.platform.conftest import SWIPL, Proc
from tests.platform.wire_client import frame, request

pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")

TOKEN = "program_hooks_token_5c1e"

# name -> (the hook's clause, the hook's name as the refusal must print it)
HOOKS = {
    "exception_hook": (
        "prolog_exception_hook(_, _, _, _) :- repeat, fail.",
        "prolog_exception_hook/4",
    ),
    "exception_hook_user": (
        "user:prolog_exception_hook(_, _, _, _) :- repeat, fail.",
        "prolog_exception_hook/4",
    ),
    "trace_interception": (
        "prolog_trace_interception(_, _, _, continue) :- repeat, fail.",
        "prolog_trace_interception/4",
    ),
    "event_hook": ("prolog_event_hook(_) :- repeat, fail.", "prolog_event_hook/1"),
    "thread_message_hook": (
        "thread_message_hook(_, _, _) :- repeat, fail.",
        "thread_message_hook/3",
    ),
    "portray_attvar": ("portray_attvar(_) :- repeat, fail.", "portray_attvar/1"),
    "predicate_name": ("prolog_predicate_name(_, _) :- repeat, fail.", "prolog_predicate_name/2"),
    "clause_name": ("prolog_clause_name(_, _) :- repeat, fail.", "prolog_clause_name/2"),
    "exception": ("exception(_, _, _) :- repeat, fail.", "exception/3"),
    "message_hook": ("message_hook(_, _, _) :- repeat, fail.", "message_hook/3"),
    "portray": ("portray(_) :- repeat, fail.", "portray/1"),
    "load_file": ("prolog_load_file(_, _) :- repeat, fail.", "prolog_load_file/2"),
    "term_expansion": ("term_expansion(_, _) :- repeat, fail.", "term_expansion/2"),
    "term_expansion4": ("term_expansion(_, _, _, _) :- repeat, fail.", "term_expansion/4"),
    "goal_expansion": ("goal_expansion(_, _) :- repeat, fail.", "goal_expansion/2"),
    "goal_expansion4": ("goal_expansion(_, _, _, _) :- repeat, fail.", "goal_expansion/4"),
    "list_goal": ("prolog_list_goal(_) :- repeat, fail.", "prolog_list_goal/1"),
    "message_property": ("message_property(_, _) :- repeat, fail.", "message_property/2"),
    "resource": ("resource(_, _, _) :- repeat, fail.", "resource/3"),
    "file_search_path": ("file_search_path(_, _) :- repeat, fail.", "file_search_path/2"),
    "library_directory": ("library_directory(_) :- repeat, fail.", "library_directory/1"),
    "expand_query": ("expand_query(_, _, _, _) :- repeat, fail.", "expand_query/4"),
    "expand_answer": ("expand_answer(_, _) :- repeat, fail.", "expand_answer/2"),
    "file_type": ("prolog_file_type(_, _) :- repeat, fail.", "prolog_file_type/2"),
    "attr_portray_hook": ("attr_portray_hook(_, _) :- repeat, fail.", "attr_portray_hook/2"),
    "attribute_goals": ("attribute_goals(_) --> { repeat, fail }.", "attribute_goals/3"),
    "stack_frame_property": (
        "prolog_stack_frame_property(_, _) :- repeat, fail.",
        "prolog_stack_frame_property/2",
    ),
    "prolog_message": ("prolog:message(_) --> { repeat, fail }.", "message/3"),
    "prolog_error_message": ("prolog:error_message(_) --> { repeat, fail }.", "error_message/3"),
    "declared_hook": (":- dynamic prolog_exception_hook/4.", "prolog_exception_hook/4"),
}

GOOD = "hook_marker(1).\nmy_portray(X) :- atom(X).\n"
CLASH_A = (
    "shared(a).\nhelper(X, Y) :- Y is X + 1.\n"
    "dfrl_aggregation:aggregate_init(clash_a, V, W) :- helper(V, W).\n"
)
CLASH_B = (
    "shared(b).\nhelper(X, Y) :- Y is X * 10.\n"
    "dfrl_aggregation:aggregate_init(clash_b, V, W) :- helper(V, W).\n"
)


def _pl_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'


def _victim(procs: list[Proc], tmp_path: Path) -> tuple[Proc, int]:
    return hostile_node.start(
        procs,
        tmp_path,
        f"[token('{TOKEN}'), agent_cpu_limit(1)]",
        consult=(PLATFORM_DIR / "dfrl_agent" / "dfrl_agent.pl",),
    )


def _attacker(
    procs: list[Proc],
    tmp_path: Path,
    port: int,
    sends: dict[str, str],
    tail: str = "",
    name: str = "attacker",
) -> Proc:
    """A console that sends each program of ``sends`` (id -> text) and prints its result."""
    calls = "\n".join(
        f"report({n}, load_program_text('127.0.0.1':{port}, {n}, {_pl_string(t)}, "
        f"[tokens(['{TOKEN}'])])),"
        for n, t in sends.items()
    )
    prog = f"""
    :- use_module({str(PLATFORM_DIR / "tartarus.pl")!r}).
    :- dynamic clash/3, good/3.
    good(guid, _, main) :- format("GOOD~n"), flush_output.
    clash(guid, _, main) :-
        dfrl_aggregation:aggregate_init(clash_a, 2, A),
        dfrl_aggregation:aggregate_init(clash_b, 2, B),
        format("CLASH ~w ~w~n", [A, B]), flush_output.
    report(Name, Goal) :-
        catch((Goal, T = ok), E, (message_to_codes(E, S), T = E-S)),
        format("RESULT ~w ~q~n", [Name, T]), flush_output.
    message_to_codes(E, S) :-
        '$messages':translate_message(E, Lines, []),
        with_output_to(string(S), print_message_lines(current_output, '', Lines)).
    main :- node_start('127.0.0.1':0, _, [token('{TOKEN}')]),
            {calls}
            {tail}
            format("DONE~n"), flush_output.
    """
    path = tmp_path / f"{name}.pl"
    path.write_text(prog)
    p = Proc([SWIPL, "-q", "-g", "main", "-t", "halt", str(path)])
    procs.append(p)
    return p


def _results(out: str) -> dict[str, str]:
    return {line.split()[1]: line for line in out.splitlines() if line.startswith("RESULT")}


#: Share of a core that tells a spinning worker from an idle node. An idle node uses about
#: 0.01; a worker spinning in a hook took 0.29 of a core while the whole suite ran on both
#: cores beside it (0.43 s over 1.5 s once), a whole core on a quiet machine.
SPIN_CORES = 0.15


def _idle_cpu(pid: int, seconds: float = 2.0) -> float:
    """The share of a core the process used over ``seconds``."""
    c0 = hostile_node.cpu_s(pid)
    time.sleep(seconds)
    return (hostile_node.cpu_s(pid) - c0) / seconds


def test_every_hook_refused_by_name(tmp_path: Path, procs: list[Proc]) -> None:
    node, port = _victim(procs, tmp_path)
    sends = {n: f"hook_marker(1).\n{clause}\n" for n, (clause, _) in HOOKS.items()}
    sends["good"] = GOOD
    a = _attacker(procs, tmp_path, port, sends)
    a.wait_for("DONE", timeout=60)
    results = _results(a.output())
    for name, (_, hook) in HOOKS.items():
        line = results.get(name, "")
        assert "permission_error(install,code,hook(" in line, (name, a.output())
        assert hook in line.split("-", 1)[-1], (name, line)  # the printed message names it
    assert results["good"].endswith(" ok"), a.output()
    # the refused exception hook is not there: a malformed frame from an unauthenticated peer
    # is answered (or the connection closed) and leaves no worker spinning
    _malformed_frame(port)
    assert _idle_cpu(node.popen.pid) < SPIN_CORES
    assert "pong" in request(port, "ping", token=TOKEN)


def _malformed_frame(port: int) -> None:
    """A malformed frame from an unauthenticated peer; the hello and the reply (or the close)
    are awaited, 5 s each at most (a node whose worker spins sends neither)."""
    with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
        try:
            s.recv(4096)  # the hello
            s.sendall(frame(b"this is ( not a term .\n"))
            s.recv(4096)
        except OSError:
            pass


def test_control_the_exception_hook_spins_when_installed(tmp_path: Path, procs: list[Proc]) -> None:
    """Control: the same hook consulted locally (trusted code, into ``user``) makes an
    unauthenticated peer's connection spin a worker (at its first exception: the hello's, or the
    malformed frame's), so the probe above can see the harm."""
    hook = tmp_path / "hook.pl"
    hook.write_text(
        ":- module(hook, []).\n:- multifile user:prolog_exception_hook/4.\n"
        "user:prolog_exception_hook(_, _, _, _) :- repeat, fail.\n"
    )
    node, port = hostile_node.start(procs, tmp_path, f"[token('{TOKEN}')]", consult=(hook,))
    _malformed_frame(port)
    assert _idle_cpu(node.popen.pid) > SPIN_CORES


def test_same_names_do_not_clash(tmp_path: Path, procs: list[Proc]) -> None:
    """Two peers (two processes) send programs that define the same names."""
    node, port = _victim(procs, tmp_path)
    a = _attacker(procs, tmp_path, port, {"prog_a": CLASH_A}, name="peer_a")
    a.wait_for("DONE", timeout=60)
    tail = (
        f"create_mobile_agent(c1, clash, ['{TOKEN}']), "
        f"report(agent, move_agent(c1, ('127.0.0.1', {port}))),"
    )
    b = _attacker(procs, tmp_path, port, {"prog_b": CLASH_B}, tail, name="peer_b")
    b.wait_for("DONE", timeout=60)
    assert _results(a.output())["prog_a"].endswith(" ok"), a.output()
    results = _results(b.output())
    assert results["prog_b"].endswith(" ok"), b.output()  # main: 'defined by another file'
    assert results["agent"].endswith(" ok"), b.output()
    assert node.wait_for("CLASH") == "CLASH 3 20"  # each method its own helper


# A spinning loop is stopped by its CPU limit, or by the wall-clock limit (5 x the CPU limit) when
# the machine is so busy that it got less than a fifth of a core: stopped either way. A sleeping
# loop uses no CPU: only the wall-clock limit stops it.
@pytest.mark.parametrize(
    "loop,kinds",
    [
        ("(repeat, fail)", ("cpu(1)", "wall_time(5)")),
        ("(repeat, sleep(0.05), fail)", ("wall_time(5)",)),
    ],
)
def test_initialization_loop_stopped(
    tmp_path: Path, procs: list[Proc], loop: str, kinds: tuple[str, ...]
) -> None:
    node, port = _victim(procs, tmp_path)
    tail = (
        f"create_mobile_agent(g1, good, ['{TOKEN}']), "
        f"report(agent, move_agent(g1, ('127.0.0.1', {port}))),"
    )
    sends = {
        "loop": f"loop_marker(1).\n:- initialization({loop}).\n",
        "after": 'after_marker(1).\n:- initialization(format("LOADED ~w~n", [after])).\n',
    }
    a = _attacker(procs, tmp_path, port, sends, tail)
    t0 = time.monotonic()
    a.wait_for("DONE", timeout=60)
    results = _results(a.output())
    assert any(
        f"resource_error(program_initialization(loop,{kind}))" in results["loop"] for kind in kinds
    ), a.output()
    assert time.monotonic() - t0 < 30
    assert results["after"].endswith(" ok"), a.output()
    assert results["agent"].endswith(" ok"), a.output()
    node.wait_for("LOADED after")
    node.wait_for("GOOD")
    assert "pong" in request(port, "ping", token=TOKEN)
    assert _idle_cpu(node.popen.pid) < SPIN_CORES  # no worker still spinning
