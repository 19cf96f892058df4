"""Helpers of the bounds tests (tests/security/test_bounds.py, test_node_budgets.py): a victim
node, an attacker process that sends agents to it, and what /proc says of a process."""

from __future__ import annotations

import os
import re
import threading
import time
from pathlib import Path

from dfrl.platform_pl import PLATFORM_DIR

from tests.platform.conftest import SWIPL, Proc

TICK = os.sysconf("SC_CLK_TCK")
MIB = 1024 * 1024


def start_victim(
    procs: list[Proc], tmp_path: Path, options: str = "", prelude: str = ""
) -> tuple[Proc, int]:
    """A node with token 5 and the given extra node options (and ``prelude``, clauses and
    directives loaded before it starts); return it and its port."""
    path = tmp_path / f"victim_{len(procs)}.pl"
    path.write_text(f"""
    :- use_module({str(PLATFORM_DIR / "tartarus.pl")!r}).
    {prelude}
    main :- node_start(localhost:0, N, [token(5), default(true){", " + options if options else ""}]),
            node_property(N, address(H:P)),
            format("dfrl node listening on ~w:~w~n", [H, P]), flush_output,
            thread_get_message(_).
    """)
    assert SWIPL
    p = Proc([SWIPL, "-q", "-g", "main", str(path)])
    procs.append(p)
    line = p.wait_for("listening on")
    return p, int(line.rsplit(":", 1)[1])


def attacker(
    procs: list[Proc], tmp_path: Path, clauses: str, body: str, node_options: str = ""
) -> Proc:
    """A process with its own node (token 5, and ``node_options``, e.g. its ``tls(Dir)``) that
    runs ``body``; its agents are ``clauses``.

    ``await_report(Name, Secs)`` prints ``REPORT Name Kind`` once the victim told this node
    that its agent Name was stopped, or ``NO REPORT Name`` after Secs.
    """
    prog = f"""
    :- use_module({str(PLATFORM_DIR / "tartarus.pl")!r}).
    :- use_module({str(PLATFORM_DIR / "agent_bounds.pl")!r}).
    :- dynamic good/3.
    good(guid, (_, P), main) :- format("GOOD at ~w~n", [P]), flush_output.
    {clauses}
    report(Goal) :-
        catch((Goal, T = ok), E, message_to_codes(E, T)),
        format("RESULT ~w~n", [T]), flush_output.
    message_to_codes(E, T) :-
        '$messages':translate_message(E, L, []),
        with_output_to(string(T), print_message_lines(current_output, '', L)).
    send(Name, Handler, Port) :-
        create_mobile_agent(Name, Handler, [5]),
        report(move_agent(Name, (localhost, Port))),
        format("SENT ~w~n", [Name]), flush_output.
    await_report(Name, Secs) :-
        current_node(Here), get_time(T0), Deadline is T0 + Secs,
        await_loop(Here, Name, Deadline).
    await_loop(Here, Name, Deadline) :-
        (   agent_bound_report(Here, Name, bound(Kind, _, _, _))
        ->  format("REPORT ~w ~q~n", [Name, Kind])
        ;   get_time(Now), Now < Deadline
        ->  sleep(0.05), await_loop(Here, Name, Deadline)
        ;   format("NO REPORT ~w~n", [Name])
        ),
        flush_output.
    main :- node_start(localhost:0, _, [token(5){", " + node_options if node_options else ""}]),
            {body}
            format("DONE~n"), flush_output.
    """
    path = tmp_path / f"attacker_{len(procs)}.pl"
    path.write_text(prog)
    assert SWIPL
    proc = Proc([SWIPL, "-q", "-g", "main", "-t", "halt", str(path)])
    procs.append(proc)
    return proc


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of process ``pid`` so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICK


def status(pid: int, key: str) -> int:
    """A numeric field of ``/proc/PID/status`` (kB for memory fields)."""
    m = re.search(rf"^{key}:\s+(\d+)", Path(f"/proc/{pid}/status").read_text(), re.M)
    assert m, key
    return int(m.group(1))


class ThreadSampler:
    """Samples the thread count of a process every 0.1 s (for at most ``limit_s``)."""

    def __init__(self, pid: int, limit_s: float = 60.0) -> None:
        self.pid, self.limit_s, self.counts = pid, limit_s, []
        self._stop = threading.Event()
        self._t = threading.Thread(target=self._run, daemon=True)
        self._t.start()

    def _run(self) -> None:
        end = time.monotonic() + self.limit_s
        while not self._stop.is_set() and time.monotonic() < end:
            try:
                self.counts.append(status(self.pid, "Threads"))
            except (OSError, AssertionError):
                return
            self._stop.wait(0.1)

    def stop(self) -> int:
        self._stop.set()
        self._t.join(5)
        return max(self.counts)
