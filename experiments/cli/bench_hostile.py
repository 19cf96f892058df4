"""``dfrl bench hostile``: its options and its output (registered in :mod:`.bench`).

The command layer of :mod:`dfrl.experiments.tools.bench.hostile`: it alone prints and chooses
the exit status (0 every phase met its targets, 1 one did not or the benchmark failed).
"""

from __future__ import annotations

import argparse
import json
import sys

from dfrl.experiments.tools.bench import hostile, hostile_verdict as verdict
from dfrl.experiments.tools.bench.hostile_attacks import FRAME_KINDS

D = hostile.HostileConfig()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``dfrl bench hostile``, each help stating its default."""
    parser.add_argument(
        "--slowloris",
        type=int,
        default=D.slowloris,
        help=f"slowloris connections, one byte a second each (default {D.slowloris})",
    )
    parser.add_argument(
        "--flood",
        type=int,
        default=D.flood,
        help=f"flood connections opened and held (default {D.flood})",
    )
    parser.add_argument(
        "--frames",
        type=int,
        default=D.frames,
        help=f"concurrent senders of large hostile frames (default {D.frames})",
    )
    parser.add_argument(
        "--frame-size",
        type=int,
        default=D.frame_size,
        help=f"bytes of the oversized frames (default {D.frame_size})",
    )
    parser.add_argument(
        "--duration",
        type=float,
        default=D.duration_s,
        help=f"seconds of each phase, quiet included (default {D.duration_s:g})",
    )
    parser.add_argument(
        "--settle",
        type=float,
        default=D.settle_s,
        help=f"seconds after each attack before RSS is read (default {D.settle_s:g})",
    )
    parser.add_argument(
        "--sources",
        type=int,
        default=D.sources,
        help=f"loopback source addresses of the attackers, from 127.0.0.2 (default {D.sources})",
    )
    parser.add_argument(
        "--pause-ms",
        type=int,
        default=D.pause_ms,
        help=f"pause of the agent between two hops (default {D.pause_ms})",
    )
    parser.add_argument(
        "--floats",
        type=int,
        default=D.floats,
        help=f"floats in the agent's payload (default {D.floats})",
    )
    parser.add_argument(
        "--pooled",
        action="store_true",
        help="reuse pooled connections to the target (default: a new "
        "connection for every hop into the target)",
    )
    parser.add_argument(
        "--attacks",
        nargs="+",
        choices=hostile.ATTACKS,
        default=list(hostile.ATTACKS),
        help=f"attacks to run, in order (default: {' '.join(hostile.ATTACKS)})",
    )
    parser.add_argument(
        "--frame-kinds",
        nargs="+",
        choices=FRAME_KINDS,
        default=list(FRAME_KINDS),
        help=f"hostile frames sent, in turn by sender (default: {' '.join(FRAME_KINDS)})",
    )
    parser.add_argument(
        "--per-wave",
        type=int,
        default=D.per_wave,
        help=f"agents per wave of loop/memory/clone/assert/log/post (default {D.per_wave})",
    )
    parser.add_argument(
        "--wave-s",
        type=float,
        default=D.wave_s,
        help=f"seconds between two waves (default {D.wave_s:g})",
    )
    parser.add_argument(
        "--escape-wait",
        type=float,
        default=D.escape_wait_s,
        help=f"seconds an accepted escape agent has to come home (default {D.escape_wait_s:g})",
    )
    parser.add_argument(
        "--clone-depth",
        type=int,
        default=D.clone_depth,
        help=f"generations of the clone bomb (2^depth agents; default {D.clone_depth})",
    )
    parser.add_argument(
        "--assert-facts",
        type=int,
        default=D.assert_facts,
        help=f"facts each assert bomb asserts (default {D.assert_facts})",
    )
    parser.add_argument(
        "--auth-big",
        type=int,
        default=D.auth_big,
        help=f"authenticated senders of big frames (default {D.auth_big})",
    )
    parser.add_argument(
        "--auth-big-mb",
        type=float,
        default=D.auth_big_mb,
        help="MiB of their frames (default 0: the target's max_frame_size less 64 KiB)",
    )
    parser.add_argument(
        "--auth-flood",
        type=int,
        default=D.auth_flood,
        help=f"authenticated senders of small requests, as fast as replies "
        f"come (default {D.auth_flood})",
    )
    parser.add_argument(
        "--trust-attacker",
        action="store_true",
        help="control run: mutual TLS, and the target trusts the attacker's "
        "code by name (trusted_peers), so escapes run and the escapes "
        "phase must fail",
    )
    parser.add_argument(
        "--threads-wait",
        type=float,
        default=D.threads_wait_s,
        help=f"seconds the target's threads have to come down to the settled "
        f"bound once its pools' idle time has passed after an attack "
        f"(default {D.threads_wait_s:g})",
    )
    parser.add_argument(
        "--pool-idle",
        type=float,
        default=D.pool_idle_s,
        help=f"the target's dfrl_pool_idle flag: seconds before a surplus idle "
        f"pool worker exits (default {D.pool_idle_s:g}, to keep the "
        f"benchmark short; 0: the node's own, 30)",
    )
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def cmd(args: argparse.Namespace) -> int:
    """Run the benchmark; exit 1 if any phase missed a target."""
    cfg = hostile.HostileConfig(
        slowloris=args.slowloris,
        flood=args.flood,
        frames=args.frames,
        frame_size=args.frame_size,
        duration_s=args.duration,
        settle_s=args.settle,
        sources=args.sources,
        pause_ms=args.pause_ms,
        floats=args.floats,
        fresh=not args.pooled,
        frame_kinds=tuple(args.frame_kinds),
        per_wave=args.per_wave,
        wave_s=args.wave_s,
        escape_wait_s=args.escape_wait,
        clone_depth=args.clone_depth,
        assert_facts=args.assert_facts,
        auth_big=args.auth_big,
        auth_big_mb=args.auth_big_mb,
        auth_flood=args.auth_flood,
        trust_attacker=args.trust_attacker,
        threads_wait_s=args.threads_wait,
        pool_idle_s=args.pool_idle,
    )
    try:
        r = hostile.run(cfg, tuple(args.attacks))
    except (ValueError, RuntimeError) as exc:  # ExperimentError is a RuntimeError
        print(f"dfrl bench hostile: {exc}", file=sys.stderr)
        return 1
    if args.json:
        print(json.dumps(r))
    else:
        print(
            f"{'phase':10s} {'hops ok/fail/unf':>17s} {'median':>8s} {'p90':>8s} "
            f"{'x quiet':>8s} {'RSS before':>10s} {'after':>7s} {'peak':>7s}  "
            f"attack connections"
        )
        for p in r["phases"]:
            h, m, a = p["hops"], p["rss_mb"], p["attack"]
            conns = (
                "-"
                if a is None
                else (
                    f"opened {a['opened']}, closed by node {a['closed_by_node']} "
                    f"(deadline {a['deadline']}, refused {a['refused']}, rejected {a['rejected']}, "
                    f"closed {a['closed']}, reset {a['reset']}), held at end {a['held_at_end']}"
                    if "opened" in a
                    else json.dumps(a.get("counts", a))[:200]
                )
            )
            print(
                f"{p['phase']:10s} {h['succeeded']:>7d}/{h['failed']}/{h['unfinished']:<7d} "
                f"{_ms(h['hop_median_ms'])} {_ms(h['hop_p90_ms'])} "
                f"{'-' if p['p90_ratio'] is None else p['p90_ratio']:>8} "
                f"{m['before']:>10.1f} {m['after']:>7.1f} {m['peak']:>7.1f}  {conns}"
            )
            t, c = p["threads"], p["cpu_cores"]
            print(
                f"{'':10s} threads {t['before']} -> peak {t['peak']} (ceiling "
                f"{t['peak_ceiling']}) -> {t['settled']} {t['settled_after_s']} s after the "
                f"attack (bound {t['settled_bound']}); ordinary agent accepted "
                f"{p['accepted_after_s']} s after; CPU {c['phase']} cores, settled "
                f"{c['settled']}; agents at end {p['agents_at_end']}"
            )
            if p["escapes"] is not None:
                e = p["escapes"]
                print(
                    f"{'':10s} escapes: {e['tried']} tried, {e['refused']} refused, "
                    f"{e['accepted']} accepted, {e['ran']} ran {e['ran_names']}"
                )
            for why in p["why"]:
                print(f"{'':10s} missed: {why}")
        print(
            f"overall: {'pass' if r['pass'] else 'FAIL'} (every hop succeeding, p90 < "
            f"{verdict.P90_RATIO_MAX:g}x quiet, RSS within {verdict.RSS_DELTA_MAX_MB:g} MB, "
            f"an ordinary agent accepted within {verdict.ACCEPT_MAX_S:g} s, threads under "
            f"the ceiling and back to the settled bound, CPU within "
            f"{verdict.CPU_MARGIN:g} cores of quiet, no escape; {r['wall_s']} s)"
        )
    return 0 if r["pass"] else 1


def _ms(v: float | None) -> str:
    return f"{'-':>8s}" if v is None else f"{v:8.2f}"
