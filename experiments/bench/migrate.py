"""Agent migration between two platform processes on loopback: ms per hop.

Runs ``bench_migrate.pl`` (beside this module) as two ``swipl`` processes (a peer and a home
node); an agent whose payload is a list of N floats bounces between them H times.
Each hop is timed from the call of ``move_agent`` at the source to the start of
the handler at the destination (same host, same clock).
"""
from __future__ import annotations

import json
import shutil
import statistics
import subprocess
from dataclasses import dataclass
from pathlib import Path

SCRIPT = Path(__file__).resolve().parent / "bench_migrate.pl"


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


def percentile(values: list[float], q: float) -> float:
    """The q-quantile (0..1) by linear interpolation between order statistics."""
    xs = sorted(values)
    if not xs:
        raise ValueError("no values")
    pos = q * (len(xs) - 1)
    lo = int(pos)
    hi = min(lo + 1, len(xs) - 1)
    return xs[lo] + (xs[hi] - xs[lo]) * (pos - lo)


def run(floats: int, hops: int, warmup: int = 2, token: int = 4242,
        timeout: float = 600, tls: str | Path | None = None) -> MigrationResult:
    """Measure ``hops`` hops (after ``warmup`` uncounted ones) with a payload of ``floats`` floats.

    With ``tls`` (a node's TLS folder: ``ca.crt``, ``node.crt``, ``node.key``, from ``dfrl certs
    node``), both platforms speak mutual TLS with that certificate.

    Raises
    ------
    ValueError
        Bad arguments.
    FileNotFoundError
        swipl is not installed.
    RuntimeError
        The benchmark scripts failed.
    """
    if floats < 0 or hops < 1 or warmup < 0:
        raise ValueError("floats >= 0, hops >= 1 and warmup >= 0 are required")
    tls_args: list[str] = []
    if tls is not None:
        from dfrl.experiments.certs import CertError, check_node_dir
        try:
            tls_args = [str(check_node_dir(tls).resolve())]
        except CertError as exc:
            raise ValueError(str(exc)) from exc
    swipl = shutil.which("swipl")
    if swipl is None:
        raise FileNotFoundError("swipl is not installed (run scripts/setup.sh)")
    peer = subprocess.Popen([swipl, "-q", str(SCRIPT), "peer", str(token), *tls_args],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert peer.stdout is not None
        line = peer.stdout.readline()
        if not line.startswith("PORT "):
            raise RuntimeError(f"peer did not start: {line!r}")
        port = int(line.split()[1])
        home = subprocess.Popen(
            [swipl, "-q", str(SCRIPT), "home", str(token), str(port), str(floats),
             str(hops + warmup), *tls_args],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            out, err = _read_latencies(home, timeout)
        finally:
            home.kill()
            home.wait(timeout=10)
    finally:
        if peer.stdin:
            peer.stdin.close()
        try:
            peer.wait(timeout=10)
        except subprocess.TimeoutExpired:
            peer.kill()
    lat_line = next((l for l in out.splitlines() if l.startswith("LATENCIES_MS")), None)
    if lat_line is None:
        raise RuntimeError(f"benchmark failed:\n{out}\n{err}")
    all_ms = json.loads(lat_line.split(" ", 1)[1])
    ms = all_ms[warmup:]
    return MigrationResult(
        floats=floats, hops=len(ms), warmup=warmup,
        median_ms=statistics.median(ms), p10_ms=percentile(ms, 0.1), p90_ms=percentile(ms, 0.9),
        min_ms=min(ms), max_ms=max(ms), mean_ms=statistics.fmean(ms),
        payload_bytes=10 * floats + 1,
    )


def _read_latencies(home: subprocess.Popen, timeout: float) -> tuple[str, str]:
    """Home's output up to its LATENCIES_MS line (or its end, or the timeout); its stderr
    when it gave none."""
    import threading

    lines: list[str] = []
    done = threading.Event()

    def read() -> None:
        assert home.stdout is not None
        for line in home.stdout:
            lines.append(line)
            if line.startswith("LATENCIES_MS"):
                break
        done.set()

    threading.Thread(target=read, daemon=True).start()
    done.wait(timeout)
    if any(l.startswith("LATENCIES_MS") for l in lines):
        return "".join(lines), ""
    home.kill()
    err = home.stderr.read() if home.stderr is not None else ""
    return "".join(lines), err


@dataclass
class TlsComparison:
    """Plaintext and TLS hops with the same payload, measured alternately (medians in ms)."""

    floats: int
    plain: MigrationResult
    tls: MigrationResult
    tls_cost: float
    """``tls.median_ms / plain.median_ms - 1`` (0.2 means TLS costs 20% more per hop)."""


def compare_tls(floats: int, hops: int, tls: str | Path, warmup: int = 2,
                rounds: int = 1) -> TlsComparison:
    """Measure plaintext and TLS hops beside each other, ``rounds`` times each, alternating
    (so a load change on the machine hits both); the figures pool every round's hops."""
    if rounds < 1:
        raise ValueError("rounds >= 1 is required")
    plain: list[MigrationResult] = []
    secure: list[MigrationResult] = []
    for _ in range(rounds):
        plain.append(run(floats, hops, warmup))
        secure.append(run(floats, hops, warmup, tls=tls))
    p, t = _pool(plain), _pool(secure)
    return TlsComparison(floats=floats, plain=p, tls=t, tls_cost=t.median_ms / p.median_ms - 1)


def _pool(results: list[MigrationResult]) -> MigrationResult:
    if len(results) == 1:
        return results[0]
    # medians of medians: each round's hops are one sample of the same distribution
    meds = [r.median_ms for r in results]
    r0 = results[0]
    return MigrationResult(
        floats=r0.floats, hops=sum(r.hops for r in results), warmup=r0.warmup,
        median_ms=statistics.median(meds), p10_ms=statistics.median(r.p10_ms for r in results),
        p90_ms=statistics.median(r.p90_ms for r in results),
        min_ms=min(r.min_ms for r in results), max_ms=max(r.max_ms for r in results),
        mean_ms=statistics.fmean(r.mean_ms for r in results), payload_bytes=r0.payload_bytes)
