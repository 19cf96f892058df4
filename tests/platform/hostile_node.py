"""A platform node with chosen options in its own ``swipl`` process, and its CPU and memory.

For the hostile-input tests: the options are a Prolog option list written by the test.
"""

from __future__ import annotations

import os
from pathlib import Path

from dfrl.platform_pl import PLATFORM_DIR

from .conftest import SWIPL, Proc

SCRIPT = """
:- use_module({tartarus!r}).
{consults}
:- initialization(main, main).
main :-
    node_start('127.0.0.1':0, N, {options}),
    node_property(N, bind(_:P)),
    format("LISTENING ~w~n", [P]),
    flush_output,
    thread_get_message(_).
"""


def start(
    procs: list[Proc],
    tmp_path: Path,
    options: str,
    name: str = "node",
    consult: tuple[Path, ...] = (),
    flags: tuple[str, ...] = (),
) -> tuple[Proc, int]:
    """Start a node with ``options`` (Prolog list text, e.g. ``"[token(9)]"``); give it and its port.

    ``consult``: files loaded (as ``use_module``) before the node starts; ``flags``: more
    ``swipl`` flags, e.g. ``--no-signals`` (as a robot process's embedded Prolog runs).
    """
    assert SWIPL, "swipl missing"
    script = tmp_path / f"{name}.pl"
    consults = "\n".join(f":- use_module({str(f)!r})." for f in consult)
    script.write_text(
        SCRIPT.format(
            tartarus=str(PLATFORM_DIR / "tartarus.pl"), options=options, consults=consults
        )
    )
    p = Proc([SWIPL, *flags, "-q", str(script)])
    procs.append(p)
    line = p.wait_for("LISTENING")
    return p, int(line.split()[1])


def rss_mb(pid: int) -> float:
    """Resident set size of process ``pid`` in MB."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise AssertionError("no VmRSS")


def cpu_s(pid: int) -> float:
    """User plus system CPU seconds used by process ``pid`` so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
