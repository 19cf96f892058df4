"""The platform across real SWI-Prolog processes on loopback."""

from __future__ import annotations

import socket
import time
from pathlib import Path

import pytest

from dfrl.platform_pl import PLATFORM_DIR

from .conftest import SWIPL, Proc, free_port, start_node
from .wire_client import connect, frame, read_frame, request

pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")

TOUR = PLATFORM_DIR / "examples" / "tartarus_tour"


def console(procs: list[Proc], tmp_path: Path, program: str, halt: bool = True) -> Proc:
    """Run ``program`` (Prolog text defining main/0) in a new swipl process."""
    path = tmp_path / f"console_{len(procs)}.pl"
    path.write_text(program)
    cmd = [SWIPL, "-q", "-g", "main"] + (["-t", "halt"] if halt else []) + [str(path)]
    proc = Proc(cmd)
    procs.append(proc)
    return proc


def wait_listening(port: int, timeout: float = 20.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            with socket.create_connection(("127.0.0.1", port), timeout=1):
                return
        except OSError:
            time.sleep(0.05)
    raise AssertionError(f"nothing listens on {port}")


def test_tartarus_program_runs_unchanged(tmp_path: Path, procs: list[Proc]) -> None:
    # Prepare: the example program, with its ports moved to free ones (as a
    # user edits the port numbers of a Tartarus program) and the path to the
    # platform pointed at this checkout.
    ports = {7001: free_port(), 7002: free_port(), 7003: free_port()}
    for src in TOUR.glob("*.pl"):
        text = src.read_text()
        for old, new in ports.items():
            text = text.replace(str(old), str(new))
        text = text.replace("'../../tartarus.pl'", repr(str(PLATFORM_DIR / "tartarus.pl")))
        (tmp_path / src.name).write_text(text)
    # Execute
    b = Proc([SWIPL, "node_b.pl"], cwd=tmp_path)
    c = Proc([SWIPL, "node_c.pl"], cwd=tmp_path)
    procs += [b, c]
    wait_listening(ports[7002])
    wait_listening(ports[7003])
    a = Proc([SWIPL, "node_a.pl"], cwd=tmp_path)
    procs.append(a)
    # Assert: the itinerary, home with what it collected, the clone, the post.
    home = a.wait_for("home with")
    assert "[alpha,bravo,charlie,alpha]" in home
    assert "tour tourist visiting alpha" in a.output()
    b.wait_for("tour tourist visiting bravo")
    c.wait_for("tour tourist visiting charlie")
    c.wait_for("mailbox got hello from tourist")
    clone = a.wait_for("sent clone").split()[-1]
    assert clone != "tourist"
    rest = b.wait_for(f"clone {clone} resting at bravo")
    assert "[alpha,charlie,bravo,alpha]" in rest


def test_three_processes_native_itinerary(tmp_path: Path, procs: list[Proc]) -> None:
    # Prepare: three nodes with the same token.
    ports = [start_node(procs, "--token", "77")[1] for _ in range(3)]
    # Execute: a console process creates an agent that visits all and returns home.
    prog = f"""
    :- use_module({str(PLATFORM_DIR / "tartarus.pl")!r}).
    :- dynamic hop/3, seen/2, home/2.
    seen(guid, []).
    hop(guid, (_, P), main) :-
        retract(seen(guid, S)), assertz(seen(guid, [P|S])),
        length(S, N), home(guid, Home),
        (   N < 2 -> N1 is N + 1, nth0(N1, {ports!r}, Next), move_agent(guid, (localhost, Next))
        ;   N =:= 2 -> move_agent(guid, (localhost, Home))
        ;   reverse([P|S], All), format("RESULT ~w~n", [All]),
            agent_hop_statistics(guid, St), format("HOPS ~w~n", [St.count]), flush_output
        ).
    main :- node_start(localhost:0, N, [token(77)]), node_property(N, address(_:Home)),
            assertz(home(guid, Home)), format("HOME ~w~n", [Home]), flush_output,
            create_mobile_agent(h1, hop, [77]), add_payload(h1, [seen/2, home/2]),
            move_agent(h1, (localhost, {ports[0]})),
            thread_get_message(_).
    """
    c = console(procs, tmp_path, prog, halt=False)
    home = int(c.wait_for("HOME").split()[1])
    expected = [*ports, home]
    # Assert
    result = c.wait_for("RESULT")
    assert result == "RESULT " + str(expected).replace(" ", "")
    assert c.wait_for("HOPS") == "HOPS 4"


def test_bad_inputs_leave_node_serving(procs: list[Proc]) -> None:
    node, port = start_node(procs, "--token", "9")
    # a port scan: connect and close, many times
    for _ in range(30):
        socket.create_connection(("127.0.0.1", port)).close()
    # idle connections that never send anything
    idle = [socket.create_connection(("127.0.0.1", port)) for _ in range(10)]
    # garbage bytes
    with connect(port) as s:
        s.sendall(b"\x00\xff garbage that is not a frame" * 10)
        reply = read_frame(s)
        assert reply is not None and "bad_magic" in reply[1]
    # an oversized frame (header claims 2 GiB)
    with connect(port) as s:
        s.sendall(frame(b"", length=2**31))
        reply = read_frame(s)
        assert reply is not None and "too_large" in reply[1]
    # a binary frame without a token proof: would crash the decoder if read
    with connect(port) as s:
        s.sendall(frame(b"\x72\x05\x02garbage", kind=b"B"))
        reply = read_frame(s)
        assert reply is not None and "binary_not_allowed" in reply[1]
    # a wrong token proof, then a binary frame
    with connect(port) as s:
        s.sendall(frame(b"auth(['00ff']) .\n"))
        verdict = read_frame(s)
        assert verdict is not None and "permission_error" in verdict[1]
        s.sendall(frame(b"\x72\x05garbage", kind=b"B"))
        reply = read_frame(s)
        assert reply is not None and "binary_not_allowed" in reply[1]
    # a syntax error and an attempt to run a goal
    assert "syntax" in request(port, "foo((((")
    assert "domain_error(platform_request" in request(port, "shell('touch /tmp/dfrl_pwned')")
    post = "post(nobody, shell, x, ['touch /tmp/dfrl_pwned'])"
    assert "permission_error(request" in request(port, post)  # posts need a token proof
    assert "existence_error(agent" in request(port, post, token="9")
    # a half-sent frame, connection left open
    half = socket.create_connection(("127.0.0.1", port))
    read_frame(half)
    half.sendall(frame(b"ping .\n")[:15])
    # the node still serves, and its process is alive
    assert request(port, "ping").startswith("ok(pong(")
    assert node.popen.poll() is None
    assert not Path("/tmp/dfrl_pwned").exists()
    for s in idle + [half]:
        s.close()


def test_unresponsive_destination_times_out_and_keeps_agent(
    tmp_path: Path, procs: list[Proc]
) -> None:
    # Prepare: a "destination" that accepts connections and never answers.
    silent = socket.socket()
    silent.bind(("127.0.0.1", 0))
    silent.listen(8)
    silent_port = silent.getsockname()[1]
    good, good_port = start_node(procs)
    prog = f"""
    :- use_module({str(PLATFORM_DIR / "tartarus.pl")!r}).
    :- dynamic h/3.
    h(guid, _, main).
    main :- node_start(localhost:0, _, [reply_timeout(1), connect_timeout(1)]),
            create_mobile_agent(a1, h, []), create_mobile_agent(a2, h, []),
            thread_create(catch(agent_move(a1, localhost:{silent_port}, []), E,
                                (print_message(informational, format("x", [])),
                                 format("STUCK_MOVE ~q~n", [E]), flush_output)), T, []),
            get_time(T0),
            move_agent(a2, (localhost, {good_port})), get_time(T1), D is T1 - T0,
            format("OTHER_MOVE_DONE ~3f~n", [D]), flush_output,
            thread_join(T, _),
            list_agents(L), format("LEFT ~w~n", [L]), flush_output.
    """
    c = console(procs, tmp_path, prog)
    # Assert: the other move is not blocked by the stuck one; the stuck one
    # times out with an error and the agent stays.
    other = c.wait_for("OTHER_MOVE_DONE")
    assert float(other.split()[1]) < 0.9
    stuck = c.wait_for("STUCK_MOVE")
    assert "transport_error" in stuck and "timeout" in stuck
    assert c.wait_for("LEFT") == "LEFT [a1]"
    silent.close()


def test_destination_killed_mid_itinerary(tmp_path: Path, procs: list[Proc]) -> None:
    victim, victim_port = start_node(procs)
    victim.stop()
    prog = f"""
    :- use_module({str(PLATFORM_DIR / "tartarus.pl")!r}).
    :- dynamic h/3.
    h(guid, _, main).
    main :- node_start(localhost:0, _, [connect_timeout(1)]),
            create_mobile_agent(a1, h, []),
            catch(move_agent(a1, (localhost, {victim_port})), E, true),
            format("ERROR ~q~n", [E]), list_agents(L), format("LEFT ~w~n", [L]).
    """
    c = console(procs, tmp_path, prog)
    assert "transport_error" in c.wait_for("ERROR")
    assert c.wait_for("LEFT") == "LEFT [a1]"


def test_remote_code_loading_injects_new_agent(tmp_path: Path, procs: list[Proc]) -> None:
    _, port = start_node(procs, "--token", "5")
    program = tmp_path / "newagent.pl"
    program.write_text(
        ":- dynamic greeter/3.\n"
        'greeter(guid, (_, P), main) :- format("GREETER ~w at ~w~n", [guid, P]), flush_output.\n'
    )
    prog = f"""
    :- use_module({str(PLATFORM_DIR / "tartarus.pl")!r}).
    main :- node_start(localhost:0, _, [token(5)]),
            load_program_at(localhost:{port}, {str(program)!r}, []),
            catch(load_program_at(localhost:{port}, {str(program)!r}, [tokens([6])]), E, true),
            format("REFUSED ~q~n", [E]), flush_output,
            load_program({str(program)!r}),
            create_mobile_agent(g1, greeter, [5]),
            move_agent(g1, (localhost, {port})),
            format("MOVED~n"), flush_output.
    """
    c = console(procs, tmp_path, prog)
    assert "permission_error(load" in c.wait_for("REFUSED")
    c.wait_for("MOVED")
    node = procs[0]
    node.wait_for(f"GREETER g1 at {port}")
