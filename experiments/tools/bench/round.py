"""One full dFRL round (forward and backward over N robot processes), ms per round.

Starts N robot processes on loopback (:mod:`dfrl.experiments.robot_host` in benchmark mode:
each holds a random table of ``--entries`` values and serves the agent's requests as soon as
they arrive, no simulation), launches the real itinerary agent
(through a console node, :mod:`dfrl.experiments.driver.console`) for ``--warmup + --rounds``
rounds without rest and reads the round times from its log (the agent stamps a round's start
when it reads the first robot and its end after writing the first robot back). Checks that
every robot holds the same table after each round. Target: median under 50 ms for 5 nodes
and 20,000 entries.

Beside the round, in the same run, it times the hops a round is made of: ``dfrl bench migrate``'s
hop with a payload of as many floats as the table has entries (``hop_median_ms``), so that
``round_over_hops`` (the round's median over ``hops`` such hops) tells whether a slower round
is slower hops or the rest of the round (reading, aggregating and writing tables, the agent's
checkpoints).

With ``learner="dqn"`` (or ``"linear"``) each robot holds, instead of a table, a random
parameter vector with the layout of that learner's network, built by the learner's own code
(:func:`dfrl.experiments.robot_host.static_robot.network_layout`: the size a real ``dqn`` robot
offers), learnt from :func:`bench_samples` samples; the agent carries parameter vectors
(``"carries": "params"``, FedAvg weighted by samples), as in a ``dfrl run`` with such robots.
Every robot saves what it holds at the end as ``params/<robot>.npy`` under ``out``.

With ``itinerary="tree"`` the agent clones itself over a tree of fan-out ``fanout`` instead of
walking the chain (as ``dfrl run`` with ``"itinerary": "tree"``); the robots' nodes then admit
the clones of :data:`~dfrl.experiments.driver.launcher.spawn.TREE_ROUNDS_PER_S` rounds a second.
"""

from __future__ import annotations

import math
import os
import statistics
import tempfile
import time
from pathlib import Path

from dfrl.experiments.driver.config import RobotSpec
from dfrl.experiments.robot_host.config import RobotConfig
from dfrl.experiments.driver.launcher.agents import launch_agent, open_console
from dfrl.experiments.driver.launcher.children import RobotChild
from dfrl.experiments.driver.launcher.robots import await_ready
from dfrl.experiments.driver.launcher.spawn import TREE_ROUNDS_PER_S
from dfrl.experiments.driver.results.agent_log import read_rounds_log
from dfrl.experiments.driver.results.rounds import count_equal, read_shares, write_rounds_csv
from dfrl.experiments.tools.bench.step_trace import ENV as STEP_TRACE_ENV, step_summary
from dfrl.experiments.tools.bench.traced_robot import MODULE as TRACED_ROBOT

TARGET_MS = 50.0

#: the token of the benchmark's console node and agent (and of a tree's robots)
TOKEN = 1111

#: ``itinerary`` values: the agent walks the robots and back, or clones itself over a tree
ITINERARIES = ("chain", "tree")

#: ``learner`` values: ``table`` (a random Q-table, the default) or a function learner's name
LEARNERS = ("table", "linear", "dqn")


def bench_samples(index: int) -> int:
    """The samples (FedAvg weight) of the benchmark's robot ``index`` (0-based) in a params
    benchmark: 1000, 2000, ... so that the average is a weighted one."""
    return 1000 * (index + 1)


def bench_layout(learner: str) -> list[tuple[str, tuple[int, ...]]]:
    """The parameter layout of a robot of the function learner ``learner`` with the default
    trainer config (what each robot of a params benchmark holds)."""
    from dfrl.experiments.robot_host.static_robot import network_layout
    from dfrl.robots.training import TrainerConfig

    return network_layout(TrainerConfig(algo=learner))


def bench(
    entries: int = 20000,
    actions: int = 4,
    robots: int = 5,
    rounds: int = 30,
    warmup: int = 3,
    method: str = "average",
    out: Path | None = None,
    hop_hops: int = 20,
    learner: str = "table",
    trace_dir: Path | None = None,
    itinerary: str = "chain",
    fanout: int = 2,
) -> dict:
    """Run the benchmark; return its figures. ``hop_hops``: how many migrate hops to time
    beside the round (0: none; the hop fields are then None). ``learner``: one of
    :data:`LEARNERS`; for a function learner ``entries`` and ``actions`` are not used.
    ``trace_dir``: every robot process times the platform's steps (:mod:`.step_trace`) and
    writes them there (``robot-<id>.jsonl``); the result then holds ``steps``, the sum per
    step. A traced round is slower (some 20 us per traced call): its ``median_ms`` is not
    the untraced figure. ``itinerary``: one of :data:`ITINERARIES`; ``fanout``: a tree's
    children per stop.

    Raises
    ------
    ValueError
        ``entries`` is not a multiple of ``actions``; an unknown ``learner`` or ``itinerary``;
        a tree's ``fanout`` under 2.
    RuntimeError
        A node did not start, the agent could not be launched or did not finish in time.
    """
    if learner not in LEARNERS:
        raise ValueError(f"--learner {learner!r}: known learners are {', '.join(LEARNERS)}")
    if itinerary not in ITINERARIES:
        raise ValueError(f"itinerary {itinerary!r}: use {' or '.join(ITINERARIES)}")
    if itinerary == "tree" and fanout < 2:
        raise ValueError(f"fanout {fanout}: a tree needs at least 2")
    params = learner != "table"
    if not params and entries % actions:
        raise ValueError(f"--entries {entries} is not a multiple of --actions {actions}")
    states = entries // actions
    layout = bench_layout(learner) if params else None
    floats = sum(math.prod(shape) for _, shape in layout) if layout else entries
    tmp = None
    if out is None:
        tmp = tempfile.TemporaryDirectory(prefix="dfrl_bench_round_")
        out = Path(tmp.name)
    out = out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    children: list[RobotChild] = []
    trace_env = _TraceEnv(trace_dir)
    try:
        for i in range(robots):
            spec = RobotSpec(f"r{i + 1}", "r1")
            bench_of: dict = (
                {"algo": learner, "bench_params": {"samples": bench_samples(i)}}
                if params
                else {"bench_table": [states, actions]}
            )
            if itinerary == "tree":
                # a tree's copies are clones: admit them; and a clone hands its table to its
                # parent in a message, which a node without a token takes only up to
                # max_text_frame_size (4,096 bytes): the robots get the run's token, as in
                # dfrl run
                bench_of["clone_limit"] = fanout * TREE_ROUNDS_PER_S * 60
                bench_of["token"] = TOKEN
            cfg = RobotConfig(
                robot=spec.id, out_dir=str(out), seed=i, events=False, progress_every=0, **bench_of
            )
            module = TRACED_ROBOT if trace_dir is not None else "dfrl.experiments.robot_host"
            children.append(RobotChild(spec, cfg, out, module=module))
            with trace_env:
                children[-1].start()
        await_ready(children, 120.0)
        log = out / "rounds_bench.log"
        if log.exists():
            log.unlink()
        total = warmup + rounds
        launch = {
            "name": "bench",
            "method": method,
            "rounds": total,
            "rest_s": 0.0,
            "rounds_log": str(log),
            "token": TOKEN,
            "timeout_s": 60.0,
            "itinerary": [
                {"host": a[0], "port": a[1], "robot": ch.spec.id}
                for ch in children
                if (a := ch.status().address)
            ],
        }
        if itinerary != "chain":
            launch["itinerary_kind"] = itinerary
            launch["fanout"] = fanout
        if params:
            launch["carries"] = "params"  # FedAvg of parameter vectors, as in dfrl run
        t0 = time.monotonic()
        with open_console(TOKEN, out / "logs" / "console.err") as console:
            launch_agent(console, launch)
        deadline = time.monotonic() + max(120.0, total * 2.0)
        agent_log = read_rounds_log(log, "bench")
        while agent_log.finished is None and time.monotonic() < deadline:
            time.sleep(0.1)
            agent_log = read_rounds_log(log, "bench")
        wall = time.monotonic() - t0
        if agent_log.finished is None:
            raise RuntimeError(
                f"the agent did not finish {total} rounds in time ({len(agent_log.rounds)} done)"
            )
    finally:
        for ch in children:
            ch.request_stop()
        for ch in children:
            ch.stop(10.0)
    ids = [ch.spec.id for ch in children]
    shares = {rid: read_shares(out / f"shares_{rid}.csv") for rid in ids}
    rows = write_rounds_csv(out / "rounds.csv", [agent_log], ids, shares)
    timed = [r for r in agent_log.rounds if r.round > warmup]
    ms = sorted(r.duration_ms for r in timed)
    hop_ms = _hop_median(floats, hop_hops)
    hops = timed[0].hops
    what: dict = (
        {
            "learner": learner,
            "floats": floats,
            "payload_bytes": 8 * floats,
            "layout": [[name, list(shape)] for name, shape in layout],
            "samples": [bench_samples(i) for i in range(robots)],
        }
        if layout
        else {"entries": entries, "shape": [states, actions]}
    )
    result = {
        "benchmark": "round",
        "robots": robots,
        **what,
        "method": method,
        "itinerary": itinerary,
        **({"fanout": fanout} if itinerary == "tree" else {}),
        "rounds": len(timed),
        "warmup": warmup,
        "median_ms": round(statistics.median(ms), 2),
        "p90_ms": round(ms[min(len(ms) - 1, int(0.9 * len(ms)))], 2),
        "min_ms": round(ms[0], 2),
        "max_ms": round(ms[-1], 2),
        "hops": hops,
        "bytes_carried": timed[0].bytes,
        "hop_floats": floats,
        "hop_median_ms": None if hop_ms is None else round(hop_ms, 3),
        "round_over_hops": (
            None if not hop_ms or not hops else round(statistics.median(ms) / (hops * hop_ms), 3)
        ),
        "all_equal_rounds": count_equal(rows),
        "total_rounds": len(rows),
        "wall_s": round(wall, 2),
        "target_ms": TARGET_MS,
        "log_problems": agent_log.unreadable
        + [f"round {a.round} aborted: {a.error}" for a in agent_log.aborted],
        # a robot the round left out (a tree's lost clone): the round measured is smaller
        "skipped": [
            f"round {r.round}: {s.robot}: {s.reason}" for r in agent_log.rounds for s in r.skipped
        ],
        "meets_target": statistics.median(ms) < TARGET_MS,
    }
    if trace_dir is not None:
        result["steps"] = [
            {
                "step": t.step,
                "calls": t.calls,
                "median_ms": round(t.median_ms, 3),
                "p90_ms": round(t.p90_ms, 3),
                "total_ms": round(t.total_ms, 1),
            }
            for t in step_summary(trace_dir)
        ]
    if tmp is not None:
        tmp.cleanup()
    return result


class _TraceEnv:
    """While entered, ``DFRL_STEP_TRACE`` names ``trace_dir`` (so a child started then traces);
    nothing for None."""

    def __init__(self, trace_dir: Path | None) -> None:
        self.value = None if trace_dir is None else str(Path(trace_dir).resolve())
        self.before: str | None = None

    def __enter__(self) -> None:
        if self.value is not None:
            Path(self.value).mkdir(parents=True, exist_ok=True)
            self.before = os.environ.get(STEP_TRACE_ENV)
            os.environ[STEP_TRACE_ENV] = self.value

    def __exit__(self, *exc: object) -> None:
        if self.value is not None:
            if self.before is None:
                os.environ.pop(STEP_TRACE_ENV, None)
            else:
                os.environ[STEP_TRACE_ENV] = self.before


def _hop_median(floats: int, hops: int) -> float | None:
    """The median of ``hops`` migrate hops with ``floats`` floats (ms), or None for 0 hops."""
    if hops <= 0:
        return None
    from dfrl.experiments.tools.bench import migrate

    return migrate.run(floats, hops, warmup=2, naive=False).median_ms
