"""Side doors of the sandbox, tried by a peer that holds the node's token (issue 16).

Real processes: a victim node (its own ``swipl``) and an attacker console with the victim's token
(or, over mutual TLS, a certificate the victim's CA signed, not trusted by name). Every escape
of the issue is tried as an arriving agent or a program; each is refused before it runs: the
attacker sees ``permission_error(install, code, Culprit)`` naming the culprit, the marker file
the escape would create does not exist, the refused agent is still at home (idle), and the
victim still takes an ordinary agent afterwards. Controls: the same handlers, run at the
attacker's own node (local code is trusted), create their markers, so a marker that stays
absent means the code did not run, not that it could not.
"""

from __future__ import annotations

import shutil
import socket
import struct
import threading
from pathlib import Path

import pytest

from dfrl.experiments.tools.certs import init_ca, make_node
from dfrl.platform_pl import PLATFORM_DIR
from tests.platform import hostile_node
from tests.platform.conftest import SWIPL, Proc

pytestmark = pytest.mark.skipif(SWIPL is None, reason="swipl not installed")

TOKEN = "escape_test_token_7f3a9c"

# name -> (handler body, a fragment of the culprit the refusal must name); {m} is the marker
ESCAPES = {
    "attr_hook": ("put_attr(V, freeze, user:shell('touch {m}')), V = 1", "put_attr("),
    "attr_hook_findall": (
        "'$bags':findall(x, (put_attr(V, freeze, user:shell('touch {m}')), V = 1), _)",
        "put_attr(",
    ),
    "message_goal": (
        "print_message(error, format(\"~@\", [shell('touch {m}')]))",
        "print_message(",
    ),
    "format_portray_goal": ("format(\"~W\", ['touch {m}', [portray_goal(shell)]])", "format("),
    "flag_double_quotes": (
        "set_prolog_flag(double_quotes, atom), shell('touch {m}')",
        "set_prolog_flag(",
    ),
    "argv_home": (
        "current_prolog_flag(argv, A), assertz(loot(guid, A)), shell('touch {m}')",
        "current_prolog_flag(argv",
    ),
    "other_payload": (
        "agent_property(_, sitter, payload(P)), assertz(loot(guid, P)), shell('touch {m}')",
        "agent_property",
    ),
    "catch_the_stop": ("catch(shell('touch {m}'), _, true)", "catch("),
    "dollar_call": ("'$'(shell('touch {m}'))", "$shell("),
    "at_halt": ("at_halt(shell('touch {m}'))", "at_halt("),
    "throw_stop": ("X = '$dfrl_purged', throw(X)", "throw("),
}
# one more of every family the sandbox refuses (code_safety.pl's table); each also runs the marker
FAMILIES = {
    "coroutine": ("freeze(V, shell('touch {m}')), V = 1", "freeze("),
    "message_text": (
        "message_to_string(format(\"~@\", [shell('touch {m}')]), _)",
        "message_to_string(",
    ),
    "occurs_check": (
        "set_prolog_flag(occurs_check, error), shell('touch {m}')",
        "set_prolog_flag(",
    ),
    "environment": (
        "getenv('DFRL_TOKEN', T), assertz(loot(guid, T)), shell('touch {m}')",
        "getenv(",
    ),
    "global_variable": ("nb_getval(k, _), shell('touch {m}')", "nb_getval("),
    "process_table": ("flag(dfrl_agent_names, _, 0), shell('touch {m}')", "flag("),
    "operator": ("op(700, xfx, ===>), shell('touch {m}')", "op("),
    "tabling": ("abolish_all_tables, shell('touch {m}')", "abolish_all_tables"),
    "loading": ("use_module(library(apply_macros)), shell('touch {m}')", "use_module("),
    "cleanup": ("setup_call_cleanup(true, true, shell('touch {m}'))", "setup_call_cleanup("),
    "abort": ("abort, shell('touch {m}')", "abort"),
    "clause_scan": ("clause(H, _), assertz(loot(guid, H)), shell('touch {m}')", "clause("),
    # the platform's foreign predicates (native/tls_direct.c swaps a connection's write BIO)
    "foreign_tls": (
        "tls:tls_direct_write(user_output, user_input, user_output), shell('touch {m}')",
        "tls:tls_direct_write/3",
    ),
    # the benchmark's hop probes: their stamps are no agent's to take (or forge)
    "hop_probe": (
        "hop_probe:hop_probe_stamps(S), assertz(loot(guid, S)), shell('touch {m}')",
        "hop_probe:hop_probe_stamps/1",
    ),
    # the dFRL agent's lease book (a node that hosts the dFRL agent has it loaded): a forged
    # checkpoint would be resurrected unchecked, and a forged epoch retires the real agent
    "lease_checkpoint": (
        "assertz(lease_book:ckpt(n, a, 9, 9, h, d, r, s, 0)), shell('touch {m}')",
        "assertz(",
    ),
    "lease_epoch": (
        "lease_book:note_epoch(n, dfrl, 99), shell('touch {m}')",
        "lease_book:note_epoch/3",
    ),
}
ESCAPES.update(FAMILIES)


def _prolog_atom(text: str) -> str:
    return "'" + text.replace("\\", "\\\\").replace("'", "\\'") + "'"


def _prolog_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def attacker(
    procs: list[Proc], tmp_path: Path, port: int, markers: dict[str, Path], node_options: str
) -> Proc:
    """A console with its own node that sends each escape as an agent, then a good agent."""
    clauses = []
    for name, (body, _) in ESCAPES.items():
        clauses.append(f"{name}(guid, _, main) :- {body.format(m=markers[name])}.")
    dynamics = ", ".join(f"{n}/3" for n in ESCAPES)
    prog = f"""
    :- use_module({str(PLATFORM_DIR / "tartarus.pl")!r}).
    :- dynamic {dynamics}, good/3, loot/2.
    {chr(10).join(clauses)}
    good(guid, (_, P), main) :- format("GOOD at ~w~n", [P]), flush_output.
    report(Name, Goal) :-
        catch((Goal, T = ok), E, T = E),
        format("RESULT ~w ~q~n", [Name, T]), flush_output.
    main :-
        node_start(localhost:0, _, {node_options}),
        forall(member(H, [{", ".join(ESCAPES)}]),
               ( atom_concat(H, '_agent', N),
                 create_mobile_agent(N, H, [{_prolog_atom(TOKEN)}]),
                 report(H, move_agent(N, (localhost, {port}))),
                 current_node(Here),
                 agent_property(Here, N, status(S)),
                 format("HOME ~w ~w~n", [H, S]), flush_output )),
        create_mobile_agent(g1, good, [{_prolog_atom(TOKEN)}]),
        report(good, move_agent(g1, (localhost, {port}))),
        format("DONE~n"), flush_output.
    """
    path = tmp_path / "attacker.pl"
    path.write_text(prog)
    proc = Proc([SWIPL, "-q", "-g", "main", "-t", "halt", str(path)])
    procs.append(proc)
    return proc


def _victim(procs: list[Proc], tmp_path: Path, options: str) -> tuple[Proc, int]:
    """A victim node with an agent `sitter` carrying a payload another agent may not read."""
    extra = tmp_path / "sitter.pl"
    extra.write_text(
        ":- dynamic user:sit/3, user:secret/2.\n"
        "user:sit(guid, _, _).\nuser:secret(guid, 'payload of sitter').\n"
        ":- initialization((node:current_node(_) -> true ; true)).\n"
    )
    return hostile_node.start(
        procs, tmp_path, options, consult=(PLATFORM_DIR / "dfrl_agent" / "dfrl_agent.pl", extra)
    )


def _check_refusals(out: str, markers: dict[str, Path]) -> None:
    results = {line.split()[1]: line for line in out.splitlines() if line.startswith("RESULT")}
    for name, (_, culprit) in ESCAPES.items():
        line = results.get(name, "")
        assert "permission_error(install,code," in line, (name, out)
        assert culprit in line, (name, line)
        assert f"HOME {name} idle" in out, (name, out)  # the agent stayed at home
        assert not markers[name].exists(), name
    assert results["good"].endswith(" ok"), out


@pytest.mark.parametrize("transport", ["token", "tls"])
def test_escapes_refused_and_agents_stay_home(
    tmp_path: Path, procs: list[Proc], transport: str
) -> None:
    markers = {n: tmp_path / f"marker_{n}" for n in ESCAPES}
    tok = _prolog_atom(TOKEN)
    if transport == "tls":
        if shutil.which("openssl") is None:
            pytest.skip("openssl missing")
        init_ca(tmp_path / "ca")
        dirs = {n: make_node(n, tmp_path / "ca").directory for n in ("victim", "peer")}
        victim_opts = f"[token({tok}), tls({str(dirs['victim'])!r})]"
        attacker_opts = f"[token({tok}), tls({str(dirs['peer'])!r})]"
    else:
        victim_opts = attacker_opts = f"[token({tok})]"
    node, port = _victim(procs, tmp_path, victim_opts)
    a = attacker(procs, tmp_path, port, markers, attacker_opts)
    a.wait_for("DONE", timeout=60)
    _check_refusals(a.output(), markers)
    node.wait_for("GOOD at")  # the node still serves


def test_control_escapes_run_when_trusted(tmp_path: Path, procs: list[Proc]) -> None:
    """The same handlers executed at the attacker's own node (trusted local code) create their
    markers: the escapes are live, and the refusals above are what kept them from running."""
    markers = {
        n: tmp_path / f"marker_{n}"
        for n in ESCAPES
        if n
        in (
            "attr_hook",
            "attr_hook_findall",
            "message_goal",
            "format_portray_goal",
            "dollar_call",
            "lease_checkpoint",
            "lease_epoch",
        )
    }
    clauses = "\n".join(
        f"{n}(guid, _, main) :- {ESCAPES[n][0].format(m=markers[n])}." for n in markers
    )
    prog = f"""
    :- use_module({str(PLATFORM_DIR / "tartarus.pl")!r}).
    :- use_module({str(PLATFORM_DIR / "dfrl_agent" / "dfrl_agent.pl")!r}).
    :- dynamic {", ".join(f"{n}/3" for n in markers)}.
    {clauses}
    main :- node_start(localhost:0, _, [token({_prolog_atom(TOKEN)})]),
            get_tartarus_details(Ip, P),
            forall(member(H, [{", ".join(markers)}]),
                   ( atom_concat(H, '_local', N), create_mobile_agent(N, H, []),
                     execute_agent(N, (Ip, P), H) )),
            sleep(1), format("DONE~n"), flush_output.
    """
    path = tmp_path / "local.pl"
    path.write_text(prog)
    p = Proc([SWIPL, "-q", "-g", "main", "-t", "halt", str(path)])
    procs.append(p)
    p.wait_for("DONE", timeout=30)
    for name, marker in markers.items():
        assert marker.exists(), (name, p.output())


def test_programs_with_side_doors_refused(tmp_path: Path, procs: list[Proc]) -> None:
    marker = tmp_path / "marker_program"
    tok = _prolog_atom(TOKEN)
    node, port = _victim(procs, tmp_path, f"[token({tok})]")
    texts = {
        "init_attr": f":- initialization((put_attr(V, freeze, user:shell('touch {marker}')), "
        "V = 1)).",
        "init_main": f":- initialization(shell('touch {marker}'), main).",
        "library": ":- use_module(library(apply_macros)).",
        "flag": ":- set_prolog_flag(double_quotes, atom).",
        "quasi": "x({|string(X)||abc|}).",
    }
    good = 'sbx_good(1).\n:- initialization(format("LOADED ~w~n", [ok])).\n'
    calls = "\n".join(
        f"report({n}, load_program_text(localhost:{port}, {n}, {_prolog_string(t)}, "
        f"[tokens([{tok}])])),"
        for n, t in texts.items()
    )
    prog = f"""
    :- use_module({str(PLATFORM_DIR / "tartarus.pl")!r}).
    report(Name, Goal) :-
        catch((Goal, T = ok), E, T = E),
        format("RESULT ~w ~q~n", [Name, T]), flush_output.
    main :- node_start(localhost:0, _, [token({tok})]),
            {calls}
            report(good, load_program_text(localhost:{port}, good,
                   {_prolog_string(good)},
                   [tokens([{tok}])])),
            format("DONE~n"), flush_output.
    """
    path = tmp_path / "programs.pl"
    path.write_text(prog)
    a = Proc([SWIPL, "-q", "-g", "main", "-t", "halt", str(path)])
    procs.append(a)
    a.wait_for("DONE", timeout=60)
    out = a.output()
    results = {line.split()[1]: line for line in out.splitlines() if line.startswith("RESULT")}
    for name in texts:
        assert "permission_error(install,code," in results[name], (name, out)
    assert results["good"].endswith(" ok"), out  # double_quotes is as it was
    node.wait_for("LOADED ok")
    assert not marker.exists()


def _frame(text: str) -> bytes:
    body = text.encode()
    return b"DFRL" + bytes([1]) + b"T\0\0" + struct.pack(">I", len(body)) + body


def test_hostile_reply_is_printed_inert(tmp_path: Path, procs: list[Proc]) -> None:
    """A peer answers a request with an error whose formal is format("~@", [shell(..)]): the
    requesting node raises it as a foreign error and prints it without running the goal."""
    marker = tmp_path / "marker_reply"
    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(4)
    port = srv.getsockname()[1]
    reply = _frame(f"error(error(format(\"~@\",[shell('touch {marker}')]),x)) .\n")

    def serve() -> None:
        srv.settimeout(20)
        for _ in range(2):  # bounded: two connections
            try:
                conn, _ = srv.accept()
            except OSError:
                return
            with conn:
                conn.sendall(reply)

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    prog = f"""
    :- use_module({str(PLATFORM_DIR / "tartarus.pl")!r}).
    main :- node_start(localhost:0, _, [token(1)]),
            catch(agent_post(localhost:{port}, x, h, l, []), E, true),
            print_message(error, E),
            format("CAUGHT ~q~n", [E]), flush_output.
    """
    path = tmp_path / "requester.pl"
    path.write_text(prog)
    p = Proc([SWIPL, "-q", "-g", "main", "-t", "halt", str(path)])
    procs.append(p)
    line = p.wait_for("CAUGHT", timeout=30)
    srv.close()
    assert "foreign_error" in line, p.output()
    assert not marker.exists()
