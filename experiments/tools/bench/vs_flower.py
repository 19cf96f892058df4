"""Flower against dFRL: the same clients' parameters through a Flower FedAvg round and a dFRL round.

For each size (floats per client) the benchmark runs, alternately, ``pairs`` times each (the
order swapped every pair: Flower first, then dFRL first, ...):

* **Flower** (the extra ``flower``: ``pip install 'dfrl[flower]'``; Flower is imported by no
  other part of dfrl): one real gRPC server process (``flwr.server.start_server``, FedAvg) and
  ``robots`` real client processes (:mod:`.flower_peer`), all on 127.0.0.1; every client holds
  the size's arrays and its ``fit`` returns the parameters it was sent unchanged. A round's time
  is the server's: from its fit instructions ready (``configure_fit`` returned, the clients
  sampled) to ``aggregate_fit`` returned (parameters sent to every client, their replies, the
  weighted average), timed by the strategy itself (:func:`.flower_peer.timed_fedavg`).
* **dFRL**: ``dfrl bench round`` (:func:`.round.bench`) with ``robots`` robot processes on
  127.0.0.1 holding the same number of floats; a round's time is the agent's, from reading
  the first robot to writing it back (forward and backward, aggregation included).

Each run does ``warmup`` untimed rounds then ``rounds`` timed ones; its figure is the median
round. What the robots and clients hold (:func:`payload`): a size that is the parameter count
of a function learner's network (4,931: ``dqn``; 771: ``linear``) is that network's layout,
carried as parameters (FedAvg weighted by samples on both sides: client ``i`` reports
``1000 (i + 1)`` examples, robot ``i`` as many samples); any other size is a Q-table of shape
``(N / 3, 3)`` when 3 divides N (243: the paper's 81 x 3), else ``(N / 4, 4)``, else
``(N, 1)``, averaged without weights on both sides (every client reports 1 example). Both sides
hold float64 values.

The ratio of a size is dFRL over Flower: the geometric mean of the pairs' ratios (each pair's
dFRL median over its Flower median), with the 95% t interval of the mean of their logarithms
(none for one pair); ``flower_ms`` and ``dfrl_ms`` are the geometric means of the pairs'
medians, so that ``ratio = dfrl_ms / flower_ms``.

Extra ``flower``: flwr 1.42.0 added 142 MB to site-packages (``du -sh``: flwr, grpcio,
cryptography, sqlalchemy, fastapi, pydantic, ...) and a 37 MB ``uv`` binary, and moved
packaging 26.4 -> 25.0, protobuf 7.36 -> 6.33, rich 15.0 -> 14.3 in this venv.

Measured on 4 December 2026 (``dfrl bench vs-flower --json``, defaults: 5 clients/robots, 3
pairs of 20 rounds after 3, 2-core machine, load 1.6 at the start; Flower ms / dFRL chain ms,
dFRL/Flower [95% interval]):

* 243 floats (table 81 x 3): 6.65 / 16.69 ms, 2.51 [2.26, 2.79]
* 4,931 floats (dqn parameters): 10.06 / 24.74 ms, 2.46 [2.13, 2.84]
* 20,000 floats (table 5000 x 4): 10.77 / 35.39 ms, 3.29 [2.33, 4.64]
* 100,000 floats (table 25000 x 4): 31.56 / 102.66 ms, 3.25 [3.11, 3.40]

With ``--itinerary tree`` (fan-out 2, same day, load 0.3): 7.37 / 37.05 ms, 5.03 [4.92, 5.14];
10.45 / 119.3 ms, 11.4 [10.3, 12.7]; 11.52 / 366.3 ms, 31.8 [28.4, 35.5]; 30.67 / 5175 ms,
169 [133, 214]: the tree's round grows with the size far faster than the chain's. Its cause
(issue 38): a clone's message to its parent went as a text frame, every byte of its packed
tables escaped and parsed (at 100,000 floats a clone's stack overflowed and robot r2 was
skipped every round), and a copy looked for its messages every 5 ms. With binary messages and
a wait that wakes on arrival, ``dfrl bench round`` (5 robots, 10 rounds after 2) gave on 4
December 2026 tree 16.6 / 29.3 / 89.2 ms against the chain's 16.0 / 32.4 / 91.1 ms at 243 /
20,000 / 100,000 floats (before: 34.2 / 366.8 / 5096 against 15.1 / 30.0 / 91.9); vs-flower
over a tree not run again since.
"""

from __future__ import annotations

import contextlib
import importlib.util
import json
import math
import os
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dfrl.experiments import processes
from dfrl.experiments.tools.bench import round as round_bench
from dfrl.experiments.tools.bench.migrate import paired_ratio

#: the sizes of issue 38: the paper's table, a dqn network, two larger vectors
SIZES = (243, 4931, 20000, 100000)

#: what to run when Flower is missing
INSTALL = "pip install 'dfrl[flower]'"

PEER = "dfrl.experiments.tools.bench.flower_peer"

#: seconds the Flower server has to open its port
SERVER_START_S = 60.0


def flower_missing() -> str | None:
    """Why the benchmark cannot run (Flower is not installed, and how to install it), or None."""
    if importlib.util.find_spec("flwr") is None:
        return f"Flower is not installed; it is an optional extra of this benchmark: {INSTALL}"
    return None


def flower_version() -> str | None:
    """The installed flwr's version (without importing it), None if it is not installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("flwr")
    except PackageNotFoundError:
        return None


@dataclass(frozen=True)
class Payload:
    """What each robot and each Flower client holds for a size.

    Attributes
    ----------
    floats : int
        The size (floats per robot or client).
    learner : str
        ``table`` (a Q-table) or a function learner's name (its network's parameters).
    shapes : list of tuple of int
        The arrays' shapes: one ``(states, actions)`` for a table, the layout for a network.
    """

    floats: int
    learner: str
    shapes: list[tuple[int, ...]]

    @property
    def params(self) -> bool:
        """Parameters (FedAvg weighted by samples), not a table (unweighted average)."""
        return self.learner != "table"

    def describe(self) -> str:
        if self.params:
            return f"{self.learner} parameters"
        return f"table {self.shapes[0][0]} x {self.shapes[0][1]}"


def payload(floats: int) -> Payload:
    """What robots and clients hold for ``floats`` floats (see the module doc)."""
    if floats < 1:
        raise ValueError(f"size {floats}: at least one float")
    for learner in ("dqn", "linear"):
        layout = round_bench.bench_layout(learner)
        if sum(math.prod(shape) for _, shape in layout) == floats:
            return Payload(floats, learner, [shape for _, shape in layout])
    actions = next(a for a in (3, 4, 1) if floats % a == 0)
    return Payload(floats, "table", [(floats // actions, actions)])


def _free_port() -> int:
    """A TCP port free on 127.0.0.1 now (Flower's legacy server takes a fixed address)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _await_port(port: int, server: subprocess.Popen[Any], log: Path) -> None:
    """Return once the server accepts connections on ``port``.

    Raises
    ------
    RuntimeError
        It exited first, or did not listen within :data:`SERVER_START_S`.
    """
    deadline = time.monotonic() + SERVER_START_S
    while time.monotonic() < deadline:
        if server.poll() is not None:
            raise RuntimeError(
                f"the Flower server exited ({server.returncode}) before listening: {_tail(log)}"
            )
        with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), 0.5):
            return
        time.sleep(0.05)
    raise RuntimeError(f"the Flower server did not listen within {SERVER_START_S:g} s")


def _tail(log: Path, lines: int = 5) -> str:
    try:
        return " | ".join(log.read_text(errors="replace").strip().splitlines()[-lines:])
    except OSError:
        return "(no log)"


def flower_run(p: Payload, robots: int, rounds: int, warmup: int, workdir: Path) -> float:
    """One Flower run: a server and ``robots`` clients, ``warmup + rounds`` rounds; the median
    of the timed rounds (ms).

    Raises
    ------
    RuntimeError
        A process failed or timed out, or a round missed a client.
    """
    workdir.mkdir(parents=True, exist_ok=True)
    total = warmup + rounds
    port = _free_port()
    report_file = workdir / "flower_rounds.json"
    report_file.unlink(missing_ok=True)
    shapes = json.dumps([list(s) for s in p.shapes])
    env = {**os.environ, "FLWR_TELEMETRY_ENABLED": "0", "GRPC_VERBOSITY": "ERROR"}
    common = ["--port", str(port), "--shapes", shapes]
    children: list[subprocess.Popen[Any]] = []
    with contextlib.ExitStack() as stack:
        try:
            server_log = workdir / "flower_server.log"
            out = stack.enter_context(open(server_log, "w", encoding="utf-8"))
            argv = [sys.executable, "-m", PEER, "server", *common, "--clients", str(robots)]
            argv += ["--rounds", str(total), "--out", str(report_file)]
            server = processes.start(argv, stdout=out, stderr=subprocess.STDOUT, env=env)
            children.append(server)
            _await_port(port, server, server_log)
            for i in range(robots):
                samples = round_bench.bench_samples(i) if p.params else 1
                log = stack.enter_context(
                    open(workdir / f"flower_client{i + 1}.log", "w", encoding="utf-8")
                )
                argv = [sys.executable, "-m", PEER, "client", *common, "--index", str(i)]
                argv += ["--samples", str(samples)]
                children.append(
                    processes.start(argv, stdout=log, stderr=subprocess.STDOUT, env=env)
                )
            limit = 60.0 + 10.0 * total
            if not processes.wait_or_stop(server, limit):
                raise RuntimeError(
                    f"the Flower server did not finish {total} rounds in {limit:g} s"
                )
            if server.returncode != 0 or not report_file.exists():
                raise RuntimeError(
                    f"the Flower server failed ({server.returncode}): {_tail(server_log)}"
                )
            for client in children[1:]:
                processes.wait_or_stop(client, 15.0)
        finally:
            for child in children:
                processes.stop(child)
    report = json.loads(report_file.read_text(encoding="utf-8"))
    ms = report["round_ms"]
    short = [i + 1 for i, n in enumerate(report["results"]) if n != robots]
    if len(ms) != total or short or any(report["failures"]):
        raise RuntimeError(
            f"Flower: {len(ms)} of {total} rounds; rounds without every client's reply: "
            f"{short or 'none'}; failures per round {report['failures']}"
        )
    return float(statistics.median(ms[warmup:]))


def dfrl_run(
    p: Payload, robots: int, rounds: int, warmup: int, itinerary: str, fanout: int
) -> tuple[float, list[str]]:
    """One dFRL run (:func:`.round.bench`, no hops timed beside it): the median round (ms) and
    its problems (rounds that left the robots different, the agent log's problems)."""
    r = round_bench.bench(
        entries=p.floats,
        actions=1 if p.params else p.shapes[0][1],
        robots=robots,
        rounds=rounds,
        warmup=warmup,
        method="average",
        hop_hops=0,
        learner=p.learner,
        itinerary=itinerary,
        fanout=fanout,
    )
    problems = list(r["log_problems"]) + [f"skipped: {s}" for s in r["skipped"]]
    if r["all_equal_rounds"] < r["total_rounds"]:
        problems.append(
            f"robots differed after {r['total_rounds'] - r['all_equal_rounds']} of "
            f"{r['total_rounds']} rounds"
        )
    return float(r["median_ms"]), problems


def ratio_interval(pairs: list[tuple[float, float]]) -> tuple[float, float | None, float | None]:
    """The geometric mean of the pairs' ``dfrl / flower`` and its 95% t interval (None, None for
    one pair): :func:`.migrate.paired_ratio`, as ``dfrl bench migrate --against`` compares two
    checkouts. ``pairs``: (flower_ms, dfrl_ms) each."""
    r = paired_ratio([d for _, d in pairs], [f for f, _ in pairs])
    return (r.mean, None, None) if math.isnan(r.low) else (r.mean, r.low, r.high)


def _geomean(values: list[float]) -> float:
    return math.exp(sum(math.log(v) for v in values) / len(values))


#: called after each pair: (floats, pair number from 1, flower_ms, dfrl_ms)
Progress = Callable[[int, int, float, float], None]


def compare(
    floats: int,
    robots: int = 5,
    pairs: int = 3,
    rounds: int = 20,
    warmup: int = 3,
    itinerary: str = "chain",
    fanout: int = 2,
    workdir: Path | None = None,
    progress: Progress | None = None,
) -> dict[str, Any]:
    """One size: ``pairs`` alternating Flower and dFRL runs; the size's entry of :func:`bench`."""
    p = payload(floats)
    runs: list[tuple[float, float]] = []
    problems: list[str] = []
    with contextlib.ExitStack() as stack:
        if workdir is None:
            workdir = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="dfrl_vs_")))
        for k in range(pairs):
            flower_ms = dfrl_ms = 0.0
            for side in ("flower", "dfrl") if k % 2 == 0 else ("dfrl", "flower"):
                if side == "flower":
                    flower_ms = flower_run(p, robots, rounds, warmup, workdir / f"pair{k + 1}")
                else:
                    dfrl_ms, found = dfrl_run(p, robots, rounds, warmup, itinerary, fanout)
                    problems += [f"pair {k + 1}: {x}" for x in found]
            runs.append((flower_ms, dfrl_ms))
            if progress is not None:
                progress(floats, k + 1, flower_ms, dfrl_ms)
    ratio, low, high = ratio_interval(runs)
    return {
        "floats": floats,
        "payload": p.describe(),
        "itinerary": itinerary,
        "flower_ms": round(_geomean([f for f, _ in runs]), 3),
        "dfrl_ms": round(_geomean([d for _, d in runs]), 3),
        "ratio": round(ratio, 4),
        "ratio_low": None if low is None else round(low, 4),
        "ratio_high": None if high is None else round(high, 4),
        "pairs": pairs,
        "pair_ms": [[round(f, 3), round(d, 3)] for f, d in runs],
        "problems": problems,
    }


def bench(
    sizes: tuple[int, ...] = SIZES,
    robots: int = 5,
    pairs: int = 3,
    rounds: int = 20,
    warmup: int = 3,
    itinerary: str = "chain",
    fanout: int = 2,
    progress: Progress | None = None,
) -> dict[str, Any]:
    """Run the benchmark (see the module doc); return its figures.

    Raises
    ------
    ValueError
        A size under 1, fewer than 2 robots, no pair or no round, a negative warm-up, an
        unknown itinerary.
    RuntimeError
        Flower is not installed (:func:`flower_missing` says so first), or a run failed.
    """
    if robots < 2 or pairs < 1 or rounds < 1 or warmup < 0:
        raise ValueError(
            f"robots {robots}, pairs {pairs}, rounds {rounds}, warmup {warmup}: need "
            f"at least 2 robots, 1 pair, 1 round and no negative warm-up"
        )
    if itinerary not in round_bench.ITINERARIES:
        raise ValueError(f"itinerary {itinerary!r}: use {' or '.join(round_bench.ITINERARIES)}")
    for n in sizes:
        payload(n)  # every size checked before anything starts
    missing = flower_missing()
    if missing is not None:
        raise RuntimeError(missing)
    t0, load = time.monotonic(), os.getloadavg()[0]
    entries = [
        compare(n, robots, pairs, rounds, warmup, itinerary, fanout, progress=progress)
        for n in sizes
    ]
    return {
        "benchmark": "vs-flower",
        "robots": robots,
        "rounds": rounds,
        "warmup": warmup,
        "itinerary": itinerary,
        **({"fanout": fanout} if itinerary == "tree" else {}),
        "flower_version": flower_version(),
        "flower_round": "server: configure_fit returned -> aggregate_fit returned",
        "dfrl_round": "agent: first robot read -> first robot written back",
        "load_1min": round(load, 2),
        "wall_s": round(time.monotonic() - t0, 1),
        "sizes": entries,
    }
