"""Agent migration between two platform processes on loopback: ms per hop.

Runs ``bench_migrate.pl`` (beside this module) as two ``swipl`` processes (a peer and a home
node); an agent whose payload is N floats bounces between them H times. The floats are
*packed* (``payload="packed"``, the default: one string, as ``float_vectors.pl`` packs the
tables the dFRL agent carries) or a Prolog list (``payload="list"``, what agents carried
before, and what any agent that keeps a plain list still carries).
Each hop is timed from the call of ``move_agent`` at the source to the start of
the handler at the destination (same host, same clock).

In the same run, against the same peer process, a *naive text hop* is timed: the agent's
record with its floats as a list (whatever ``payload``: the naive hop is a naive
implementation's) written as text (``write_canonical``) on a plain socket and read back with
``read_term`` by the peer, which answers ``ok``. The hop's median over the naive hop's median
(``naive_ratio``) is the figure to watch: it does not move with the machine's load the way
milliseconds do, so a regression in the hop shows in every run (target at 100,000 floats:
at most 0.20).

With ``trace_dir``, both processes time the steps of every hand-over (see
``bench_migrate.pl``) and :func:`phase_breakdown` sums them up per step.

:func:`compare_checkouts` times this checkout's hop beside another checkout's (a git worktree
of an older commit), alternating in the same minutes: on a shared machine only such a
comparison tells whether a change made the hop faster.
"""

from __future__ import annotations

import json
import math
import statistics
import subprocess
from dataclasses import dataclass
from pathlib import Path

from dfrl.experiments import processes
from dfrl.experiments.science.statistics import paired
from dfrl.experiments.tokens import env_with_tokens
from dfrl.experiments.tools.bench.step_trace import ENV as STEP_TRACE_ENV, read_steps

SCRIPT = Path(__file__).resolve().parent / "bench_migrate.pl"

PROBE_ENV = "DFRL_HOP_PROBE"
"""Set (to a folder) in a node process's environment, it compiles the platform's hop probes in
(``platform_pl/hop_probe.pl``); ``bench_migrate.pl`` writes their stamps to that folder."""

#: how the agent carries its floats: packed (the dFRL agent's tables) or a list
PAYLOADS = ("packed", "list")


@dataclass
class MigrationResult:
    """Per-hop latency figures of one run (milliseconds)."""

    floats: int
    hops: int
    warmup: int
    median_ms: float
    p10_ms: float
    p90_ms: float
    min_ms: float
    max_ms: float
    mean_ms: float
    payload_bytes: int
    payload: str = "list"
    """How the floats were carried: ``packed`` or ``list`` (see :data:`PAYLOADS`)."""
    naive_median_ms: float | None = None
    """Median of the naive text hop with the same payload, same run (None: not measured)."""
    naive_ratio: float | None = None
    """``median_ms / naive_median_ms``."""
    cpu_ms_per_hop: float | None = None
    """CPU time of both processes together per timed hop (all threads, user and system; see
    :func:`cpu_per_hop`), or None if the benchmark program did not report it (an older
    checkout's)."""
    native: bool | None = None
    """Whether the home process ran the platform's foreign code (bulk frame writes and packed
    maths, ``platform_pl/native``; both or it says false), None if its benchmark program does
    not say (an older checkout's)."""
    tls_direct: bool | None = None
    """Whether the home process's TLS connections write records straight to the socket
    (``platform_pl/native/tls_direct.c``; measured only with ``--tls``), None if its benchmark
    program does not say."""


TLS_DIRECT_REFUSED = "native/tls_direct.so does not recognise"
"""What tls.pl prints (once) when its direct write refuses a connection."""


def percentile(values: list[float], q: float) -> float:
    """The q-quantile (0..1) by linear interpolation between order statistics."""
    xs = sorted(values)
    if not xs:
        raise ValueError("no values")
    pos = q * (len(xs) - 1)
    lo = int(pos)
    hi = min(lo + 1, len(xs) - 1)
    return xs[lo] + (xs[hi] - xs[lo]) * (pos - lo)


def run(
    floats: int,
    hops: int,
    warmup: int = 2,
    token: int = 4242,
    timeout: float = 600,
    tls: str | Path | None = None,
    naive: bool = True,
    trace_dir: str | Path | None = None,
    script: Path | None = None,
    payload: str = "packed",
    probe_dir: str | Path | None = None,
) -> MigrationResult:
    """Measure ``hops`` hops (after ``warmup`` uncounted ones) with a payload of ``floats`` floats,
    ``payload`` ``packed`` or ``list`` (:data:`PAYLOADS`).

    With ``tls`` (a node's TLS folder: ``ca.crt``, ``node.crt``, ``node.key``, from ``dfrl certs
    node``), both platforms speak mutual TLS with that certificate. With ``naive`` (default),
    the naive text hop is timed too (as many hops, after as many warm-up ones), against the
    same peer process. With ``trace_dir`` (an existing folder), the processes write their step
    timings there (``home.jsonl``, ``peer.jsonl``; see :func:`phase_breakdown`). With
    ``probe_dir`` (an existing folder), the platform is compiled with its hop probes and the
    processes write their stamps there (``home.probe``, ``peer.probe``; see
    ``hop_timeline.py``). ``script``: the
    benchmark's node program to run (default :data:`SCRIPT`; :func:`compare_checkouts` passes
    another checkout's, which loads that checkout's platform).

    Raises
    ------
    ValueError
        Bad arguments.
    ExperimentError
        swipl is not installed.
    RuntimeError
        The benchmark scripts failed.
    """
    if floats < 0 or hops < 1 or warmup < 0:
        raise ValueError("floats >= 0, hops >= 1 and warmup >= 0 are required")
    if payload not in PAYLOADS:
        raise ValueError(f"payload must be one of {', '.join(PAYLOADS)}, not {payload!r}")
    tls_args: list[str] = []
    if tls is not None:
        from dfrl.experiments.tls_folder import CertError, check_node_dir

        try:
            tls_args = [str(check_node_dir(tls).resolve())]
        except CertError as exc:
            raise ValueError(str(exc)) from exc
    swipl = processes.swipl()
    program = str(script if script is not None else SCRIPT)
    env = env_with_tokens([token])  # the token in the environment, never in argv
    if trace_dir is not None:
        # step_trace.pl's variable; checkouts older than it read DFRL_HOP_TRACE
        env[STEP_TRACE_ENV] = env["DFRL_HOP_TRACE"] = str(Path(trace_dir).resolve())
    else:
        env.pop(STEP_TRACE_ENV, None)
        env.pop("DFRL_HOP_TRACE", None)
    if probe_dir is not None:
        env[PROBE_ENV] = str(Path(probe_dir).resolve())
    else:
        env.pop(PROBE_ENV, None)
    naive_ms: list[float] | None = None
    peer = processes.start(
        [swipl, "-q", program, "peer", *tls_args],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        env=env,
    )
    try:
        assert peer.stdout is not None
        line = peer.stdout.readline()
        if not line.startswith("PORT "):
            raise RuntimeError(f"peer did not start: {line!r}")
        words = line.split()
        port, naive_port = int(words[1]), int(words[3])
        home = processes.start(
            [
                swipl,
                "-q",
                program,
                "home",
                str(port),
                f"packed:{floats}" if payload == "packed" else str(floats),
                str(hops + warmup),
                *tls_args,
            ],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            env=env,
        )
        try:
            out, err = _read_latencies(home, timeout)
        finally:
            _finish(home)
        if naive:
            naive_ms = _naive_hops(swipl, program, env, naive_port, floats, hops + warmup, timeout)
            naive_ms = naive_ms[warmup:]
    finally:
        _finish(peer)
    figures = _hop_figures(out)
    if figures is None:
        raise RuntimeError(f"benchmark failed:\n{out}\n{err}")
    all_ms, stamps = figures
    ms = all_ms[warmup:]
    native_line = next((l for l in out.splitlines() if l.startswith("NATIVE")), None)
    native_words = [] if native_line is None else native_line.split()[1:]
    native = None if native_line is None else native_words[:2] == ["true", "true"]
    # the library loaded (its word), and no connection refused by its checks (tls.pl warns)
    tls_direct = (
        native_words[2] == "true" and TLS_DIRECT_REFUSED not in err
        if len(native_words) > 2
        else None
    )
    cpu_ms = None if stamps is None else cpu_per_hop(stamps, warmup)
    median = statistics.median(ms)
    naive_median = statistics.median(naive_ms) if naive_ms else None
    return MigrationResult(
        floats=floats,
        hops=len(ms),
        warmup=warmup,
        median_ms=median,
        p10_ms=percentile(ms, 0.1),
        p90_ms=percentile(ms, 0.9),
        min_ms=min(ms),
        max_ms=max(ms),
        mean_ms=statistics.fmean(ms),
        payload_bytes=10 * floats + 1,
        payload=payload,
        naive_median_ms=naive_median,
        naive_ratio=median / naive_median if naive_median else None,
        cpu_ms_per_hop=cpu_ms,
        native=native,
        tls_direct=tls_direct,
    )


def _hop_figures(out: str) -> tuple[list[float], list[list[float]] | None] | None:
    """The hop times (ms) and the CPU stamps ``[port, seconds]`` (one per arrival) in a home
    process's output: its ``ARRIVAL`` lines up to ``ARRIVALS_END``, or, from a checkout older
    than them, its ``LATENCIES_MS`` and ``CPU_S`` lines (CPU stamps None if it printed none).
    None if the output has neither."""
    lines = out.splitlines()
    old = next((l for l in lines if l.startswith("LATENCIES_MS")), None)
    if old is not None:
        cpu = next((l for l in lines if l.startswith("CPU_S")), None)
        return (
            json.loads(old.split(" ", 1)[1]),
            None if cpu is None else json.loads(cpu.split(" ", 1)[1]),
        )
    if "ARRIVALS_END" not in lines:
        return None
    ms: list[float] = []
    stamps: list[list[float]] = []
    for line in lines:
        words = line.split()
        if len(words) == 4 and words[0] == "ARRIVAL":
            if words[1] != "-":
                ms.append(float(words[1]))
            stamps.append([int(words[2]), float(words[3])])
    return ms, stamps


def cpu_per_hop(stamps: list[list[float]], warmup: int) -> float | None:
    """Both processes' CPU time per hop (ms) from the agent's stamps ``[port, seconds]``, one
    per arrival (index 0: its start at home, index i: its arrival after hop i), over the hops
    after the first ``warmup``.

    Each process takes part in every hop (as source or destination), so its CPU time between
    its first and its last stamp in the window, over the hops between them, is its CPU per hop;
    the figure is the sum over the two processes. None if a process has fewer than two stamps
    in the window.
    """
    by_port: dict[int, list[tuple[int, float]]] = {}
    for i, (port, seconds) in enumerate(stamps):
        if i >= warmup:
            by_port.setdefault(int(port), []).append((i, float(seconds)))
    total = 0.0
    for points in by_port.values():
        (i0, c0), (i1, c1) = points[0], points[-1]
        if i1 == i0:
            return None
        total += (c1 - c0) * 1000 / (i1 - i0)
    return total if by_port else None


def _finish(proc: subprocess.Popen) -> None:
    """Close a benchmark process's standard input (it then stops its node and, when tracing,
    writes its steps) and wait for it; kill it if it does not end within 10 s."""
    try:
        if proc.stdin:
            proc.stdin.close()
    except OSError:
        pass
    processes.wait_or_stop(proc, timeout_s=10)


def _naive_hops(
    swipl: str,
    program: str,
    env: dict[str, str],
    naive_port: int,
    floats: int,
    hops: int,
    timeout: float,
) -> list[float]:
    """The naive text hop's figures (ms), ``hops`` of them, from the ``naive`` mode of
    ``program`` (``env`` carries the token)."""
    done = subprocess.run(
        [swipl, "-q", program, "naive", str(naive_port), str(floats), str(hops)],
        stdin=subprocess.DEVNULL,
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
    )
    line = next((l for l in done.stdout.splitlines() if l.startswith("NAIVE_MS")), None)
    if line is None:
        raise RuntimeError(f"naive hop failed:\n{done.stdout}\n{done.stderr}")
    return [float(x) for x in json.loads(line.split(" ", 1)[1])]


@dataclass
class Phase:
    """One step of the hand-over, over the timed hops: its median duration, and the median
    time from the hop's start (the source's export of the agent) to its start."""

    step: str
    side: str
    """``source`` (the process the agent leaves) or ``destination``."""
    calls: int
    median_ms: float
    median_start_ms: float


def phase_breakdown(trace_dir: str | Path, warmup: int = 2) -> list[Phase]:
    """The steps of the hops traced into ``trace_dir`` (by :func:`run` with ``trace_dir``),
    in the order they happen within a hop.

    A hop starts with an ``export`` (in the process the agent leaves) and ends with the
    ``agent_run`` that starts its handler at the other end; the first ``warmup`` hops are left
    out.
    """
    steps = [(r.t0, r.t1, r.step, r.role) for r in read_steps(trace_dir, ["home", "peer"])]
    exports = [s for s in steps if s[2] == "export"]
    if len(exports) <= warmup:
        return []
    per: dict[tuple[str, str], list[tuple[float, float]]] = {}
    for i, start in enumerate(exports[warmup:], start=warmup):
        end = exports[i + 1][0] if i + 1 < len(exports) else float("inf")
        for t0, t1, step, process in steps:
            if start[0] <= t0 < end:
                side = "source" if process == start[3] else "destination"
                per.setdefault((step, side), []).append(((t1 - t0) * 1000, (t0 - start[0]) * 1000))
                if step == "agent_run" and process != start[3]:
                    break
    hops = len(exports) - warmup
    phases = [
        Phase(
            step,
            side,
            len(v),
            statistics.median(d for d, _ in v),
            statistics.median(s for _, s in v),
        )
        for (step, side), v in per.items()
        if len(v) >= hops // 2
    ]
    return sorted(phases, key=lambda p: p.median_start_ms)


#: the line that ends a home process's figures (LATENCIES_MS: a checkout older than ARRIVAL lines)
_LAST_LINES = ("ARRIVALS_END", "LATENCIES_MS")


def _read_latencies(home: subprocess.Popen, timeout: float) -> tuple[str, str]:
    """Home's output up to its last line of figures (or its end, or the timeout); its stderr
    when it gave none."""
    import threading

    lines: list[str] = []
    done = threading.Event()

    def read() -> None:
        assert home.stdout is not None
        for line in home.stdout:
            lines.append(line)
            if line.startswith(_LAST_LINES):
                break
        done.set()

    threading.Thread(target=read, daemon=True).start()
    done.wait(timeout)
    if any(l.startswith(_LAST_LINES) for l in lines):
        return "".join(lines), ""
    processes.stop(home)
    err = home.stderr.read() if home.stderr is not None else ""
    return "".join(lines), err


@dataclass(frozen=True)
class RatioInterval:
    """How two conditions measured in pairs of runs compare: each pair's ratio of run medians
    (runs side by side in the same minutes, so that a change in the machine's speed hits both
    of a pair), their geometric mean, and the 95% t interval of that mean (taken on the logs,
    df = pairs - 1, and turned back into a ratio). With one pair, ``low`` and ``high`` are
    NaN: one pair says nothing of the spread."""

    ratios: list[float]
    mean: float
    low: float
    high: float

    def __str__(self) -> str:
        if math.isnan(self.low):
            return f"{self.mean:.3f} (1 pair)"
        return (
            f"{self.mean:.3f} [{self.low:.3f}, {self.high:.3f}] "
            f"(95% interval, {len(self.ratios)} pairs)"
        )


def paired_ratio(a_ms: list[float], b_ms: list[float]) -> RatioInterval:
    """Compare run medians ``a_ms[i]`` and ``b_ms[i]`` measured as pair ``i`` (see
    :class:`RatioInterval`).

    Raises
    ------
    ValueError
        Lengths differ, no pairs, or a figure that is not a positive number.
    """
    if len(a_ms) != len(b_ms):
        raise ValueError(f"paired runs need equal counts, got {len(a_ms)} and {len(b_ms)}")
    if not a_ms:
        raise ValueError("no pairs of runs")
    if any(not (x > 0) for x in [*a_ms, *b_ms]):  # also NaN
        raise ValueError(f"run medians must be positive: {a_ms} against {b_ms}")
    iv = paired([math.log(a) for a in a_ms], [math.log(b) for b in b_ms])  # half: NaN for 1
    return RatioInterval(
        [a / b for a, b in zip(a_ms, b_ms)],
        math.exp(iv.mean),
        math.exp(iv.mean - iv.half),
        math.exp(iv.mean + iv.half),
    )


@dataclass
class TlsComparison:
    """Plaintext and TLS hops with the same payload, measured alternately (medians in ms)."""

    floats: int
    plain: MigrationResult
    tls: MigrationResult
    tls_cost: float
    """``tls.median_ms / plain.median_ms - 1`` (0.2 means TLS costs 20% more per hop)."""
    rounds: RatioInterval | None = None
    """TLS against plaintext, round by round (each round runs plaintext, then TLS): how far
    the cost moves with the machine; None for one round."""


def compare_tls(
    floats: int,
    hops: int,
    tls: str | Path,
    warmup: int = 2,
    rounds: int = 1,
    payload: str = "packed",
) -> TlsComparison:
    """Measure plaintext and TLS hops beside each other, ``rounds`` times each, alternating
    (so a load change on the machine hits both); the figures pool every round's hops."""
    if rounds < 1:
        raise ValueError("rounds >= 1 is required")
    plain: list[MigrationResult] = []
    secure: list[MigrationResult] = []
    for _ in range(rounds):
        plain.append(run(floats, hops, warmup, payload=payload))
        secure.append(run(floats, hops, warmup, tls=tls, naive=False, payload=payload))
    p, t = _pool(plain), _pool(secure)
    paired = (
        paired_ratio([r.median_ms for r in secure], [r.median_ms for r in plain])
        if rounds > 1
        else None
    )
    return TlsComparison(
        floats=floats, plain=p, tls=t, tls_cost=t.median_ms / p.median_ms - 1, rounds=paired
    )


def _all_or_none(flags: list[bool | None]) -> bool | None:
    return None if any(f is None for f in flags) else all(flags)


def _pool(results: list[MigrationResult]) -> MigrationResult:
    if len(results) == 1:
        return results[0]
    # medians of medians: each round's hops are one sample of the same distribution
    meds = [r.median_ms for r in results]
    r0 = results[0]
    naive = [r.naive_median_ms for r in results if r.naive_median_ms is not None]
    naive_median = statistics.median(naive) if naive else None
    return MigrationResult(
        floats=r0.floats,
        hops=sum(r.hops for r in results),
        warmup=r0.warmup,
        median_ms=statistics.median(meds),
        p10_ms=statistics.median(r.p10_ms for r in results),
        p90_ms=statistics.median(r.p90_ms for r in results),
        min_ms=min(r.min_ms for r in results),
        max_ms=max(r.max_ms for r in results),
        mean_ms=statistics.fmean(r.mean_ms for r in results),
        payload_bytes=r0.payload_bytes,
        payload=r0.payload,
        naive_median_ms=naive_median,
        naive_ratio=statistics.median(meds) / naive_median if naive_median else None,
        cpu_ms_per_hop=_median_or_none([r.cpu_ms_per_hop for r in results]),
        native=r0.native,
        tls_direct=_all_or_none([r.tls_direct for r in results]),
    )


def _median_or_none(xs: list[float | None]) -> float | None:
    """The median of the figures that are not None (None if there are none)."""
    got = [x for x in xs if x is not None]
    return statistics.median(got) if got else None


@dataclass
class CheckoutComparison:
    """This checkout's hops beside another checkout's, run alternately in the same minutes
    (medians over the runs of each; ms)."""

    floats: int
    runs: int
    this_median_ms: float
    other_median_ms: float
    this_over_other: float
    """``this_median_ms / other_median_ms`` (below 1: this checkout hops faster)."""
    this_naive_ratio: float | None
    other_naive_ratio: float | None
    this_runs_ms: list[float]
    other_runs_ms: list[float]
    this_cpu_ms_per_hop: float | None = None
    """Median over this checkout's runs of both processes' CPU per hop (see
    :func:`cpu_per_hop`)."""
    other_cpu_ms_per_hop: float | None = None
    """The same for the other checkout (None if its benchmark program reports no CPU)."""
    this_payload: str = "list"
    other_payload: str = "list"
    """How each checkout's agent carried the floats: an older checkout whose benchmark
    cannot pack them carries a list (as its agents did)."""
    pairs: RatioInterval | None = None
    """This checkout against the other, run by run (run ``i`` of each is a pair, measured
    one right after the other); None for one run each."""


def other_script(root: str | Path) -> Path:
    """The benchmark's node program in the checkout at ``root``.

    Raises
    ------
    ValueError
        ``root`` holds no ``experiments/tools/bench/bench_migrate.pl``.
    """
    script = Path(root).resolve() / "experiments" / "tools" / "bench" / "bench_migrate.pl"
    if not script.is_file():
        raise ValueError(
            f"{root}: no experiments/tools/bench/bench_migrate.pl there "
            "(give the root of a dfrl checkout, e.g. a git worktree)"
        )
    return script


def compare_checkouts(
    floats: int,
    hops: int,
    other_root: str | Path,
    runs: int = 3,
    warmup: int = 2,
    payload: str = "packed",
) -> CheckoutComparison:
    """Time this checkout's hop and the one of the checkout at ``other_root`` (say a worktree
    of an older commit), ``runs`` runs each, alternating which goes first, so that a change in
    the machine's load hits both; each run times its own naive text hop too.

    Raises
    ------
    ValueError
        Bad arguments, or ``other_root`` is no checkout (see :func:`other_script`).
    """
    if runs < 1:
        raise ValueError("runs >= 1 is required")
    other = other_script(other_root)
    other_payload = payload if "packed:" in other.read_text(encoding="utf-8") else "list"
    mine: list[MigrationResult] = []
    theirs: list[MigrationResult] = []
    for i in range(runs):
        order = [(mine, None, payload), (theirs, other, other_payload)]
        for results, script, kind in order if i % 2 == 0 else order[::-1]:
            results.append(run(floats, hops, warmup, script=script, payload=kind))

    def ratio(rs: list[MigrationResult]) -> float | None:
        xs = [r.naive_ratio for r in rs if r.naive_ratio is not None]
        return statistics.median(xs) if xs else None

    this_ms = [r.median_ms for r in mine]
    other_ms = [r.median_ms for r in theirs]
    return CheckoutComparison(
        floats=floats,
        runs=runs,
        this_median_ms=statistics.median(this_ms),
        other_median_ms=statistics.median(other_ms),
        this_over_other=statistics.median(this_ms) / statistics.median(other_ms),
        this_naive_ratio=ratio(mine),
        other_naive_ratio=ratio(theirs),
        this_runs_ms=this_ms,
        other_runs_ms=other_ms,
        this_cpu_ms_per_hop=_median_or_none([r.cpu_ms_per_hop for r in mine]),
        other_cpu_ms_per_hop=_median_or_none([r.cpu_ms_per_hop for r in theirs]),
        this_payload=payload,
        other_payload=other_payload,
        pairs=paired_ratio(this_ms, other_ms) if runs > 1 else None,
    )
