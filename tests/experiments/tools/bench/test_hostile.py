"""``dfrl bench hostile`` on a small budget: real ``swipl`` nodes, real attack sockets."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest

from dfrl.experiments.tools.bench import hostile, hostile_verdict as verdict
from dfrl.experiments.tools.bench.hostile_attacks import (
    FRAME_KINDS,
    PRE_AUTH_LIMIT,
    frame_header,
    hostile_frame,
    outcome_of,
)
from dfrl.experiments.tools.bench.hostile_auth_attacks import escape_results
from dfrl.platform_pl import PLATFORM_DIR
from dfrl.experiments.processes import find_swipl

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")


def test_outcome_of_reads_the_nodes_last_error_frame() -> None:
    hello = frame_header(9) + b"hello(1) "
    err = b"error(error(wire_error(deadline(5)),_))"
    assert outcome_of(hello) == "closed"
    assert outcome_of(hello + frame_header(len(err)) + err) == "deadline"
    busy = b"error(error(resource_error(connections),_))"
    assert outcome_of(hello + frame_header(len(busy)) + busy) == "refused"


def test_hostile_frames_have_their_stated_size() -> None:
    big = hostile_frame("chain_big", 10_000)
    assert len(big) - 12 <= 10_000 and big[12:16] == b"a+a+" and big.endswith(b"a .\n")
    assert int.from_bytes(big[8:12], "big") == len(big) - 12
    nested = hostile_frame("nested_limit", 10_000)
    assert PRE_AUTH_LIMIT - 128 < len(nested) - 12 < PRE_AUTH_LIMIT and nested[12:14] == b"[["
    call = hostile_frame("call_limit", 10_000)
    assert len(call) - 12 < PRE_AUTH_LIMIT and call[12:16] == b"f(f(" and call.endswith(b") .\n")
    binary = hostile_frame("binary_big", 5000)
    assert binary[5:6] == b"B" and int.from_bytes(binary[8:12], "big") == 5000


def test_frames_just_under_the_limit_follow_the_nodes_limit() -> None:
    out = subprocess.run(
        [
            "swipl",
            "-q",
            "-g",
            f"use_module('{PLATFORM_DIR / 'node.pl'}')",
            "-g",
            "node_registry:option_default(max_text_frame_size, B), write(B)",
            "-t",
            "halt",
        ],
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert out.stdout.strip() == str(PRE_AUTH_LIMIT), out.stderr


@pytest.mark.slow  # ~30 s; the authenticated phases and escapes tests below cover the bench in the default suite
def test_small_hostile_benchmark_keeps_hops_succeeding() -> None:
    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "dfrl",
            "bench",
            "hostile",
            "--slowloris",
            "10",
            "--flood",
            "50",
            "--frames",
            "6",
            "--frame-size",
            "200000",
            "--duration",
            "4",
            "--settle",
            "1",
            "--threads-wait",
            "3",
            "--pool-idle",
            "1",
            "--attacks",
            "slowloris",
            "flood",
            "frames",
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    r = json.loads(out.stdout)
    assert [p["phase"] for p in r["phases"]] == ["quiet", "slowloris", "flood", "frames"]
    for p in r["phases"]:
        h = p["hops"]
        assert h["succeeded"] > 10 and h["failed"] == 0 and h["unfinished"] == 0, p
        assert h["attempted"] == h["succeeded"]
        assert 0 < h["hop_median_ms"] <= h["hop_p90_ms"]
        assert set(p["rss_mb"]) == {"before", "after", "after_settle_s", "peak", "delta"}
        assert abs(p["rss_mb"]["delta"] - (p["rss_mb"]["after"] - p["rss_mb"]["before"])) <= 0.11
        assert isinstance(p["pass"], bool)
    quiet, slow, flood, frames = r["phases"]
    assert quiet["attack"] is None and quiet["p90_ratio"] is None
    assert slow["attack"]["opened"] >= 10 and flood["attack"]["opened"] >= 50
    assert flood["attack"]["closed_by_node"] > 0  # 50 > the 32 unauthenticated slots
    assert frames["attack"]["rejected"] > 0
    assert frames["attack"]["reject_reasons"].get("too_large", 0) > 0
    assert frames["attack"]["reject_reasons"].get("too_deep", 0) > 0
    assert set(frames["attack"]["frames_by_kind"]) == set(FRAME_KINDS)
    assert r["pass"] == all(p["pass"] for p in r["phases"])
    assert out.returncode == (0 if r["pass"] else 1), out.stderr[-2000:]


def _hostile(*args: str, timeout: float = 60) -> tuple[dict, subprocess.CompletedProcess]:
    out = subprocess.run(
        [sys.executable, "-m", "dfrl", "bench", "hostile", *args, "--json"],
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    assert out.stdout.startswith("{"), out.stderr[-3000:]
    return json.loads(out.stdout), out


def test_escape_results_decide_ran_from_markers_reports_and_the_flag(tmp_path) -> None:
    marker = tmp_path / "agent_freeze_handler"
    marker.touch()
    attempts = [
        {
            "name": "freeze_handler",
            "via": "agent",
            "verdict": "accepted",
            "marker": str(marker),
            "reported": False,
            "carried": None,
        },
        {
            "name": "argv",
            "via": "agent",
            "verdict": "accepted",
            "marker": str(tmp_path / "x"),
            "reported": True,
            "carried": "[target,'4243']",
        },
        {
            "name": "other_payload",
            "via": "agent",
            "verdict": "refused",
            "marker": str(tmp_path / "y"),
            "reported": False,
            "carried": None,
            "error": "e",
        },
        {
            "name": "double_quotes",
            "via": "program",
            "verdict": "error",
            "marker": str(tmp_path / "z"),
            "reported": False,
            "carried": None,
        },
    ]
    e = escape_results(attempts, 4243, "codes", "atom")
    assert [a["ran"] for a in e["attempts"]] == [True, True, False, True]
    assert e["attempts"][1]["leaked_token"] is True
    assert (e["tried"], e["refused"], e["accepted"], e["ran"]) == (4, 1, 2, 3)
    assert escape_results(attempts[2:3], 4243, "codes", "codes")["ran"] == 0


AUTH_SHORT = (
    "--duration",
    "3",
    "--settle",
    "1",
    "--pool-idle",
    "1",
    "--threads-wait",
    "5",
    "--escape-wait",
    "2",
    "--wave-s",
    "2",
)


def test_authenticated_phases_have_their_figures_and_no_escape_runs() -> None:
    r, out = _hostile(
        "--attacks",
        "escapes",
        "loop",
        "authframes",
        "--auth-big-mb",
        "1",
        "--auth-flood",
        "2",
        *AUTH_SHORT,
    )
    assert [p["phase"] for p in r["phases"]] == ["quiet", "escapes", "loop", "authframes"]
    limits = r["targets"]["target_limits"]
    assert r["targets"]["target_pool_idle_s"] == 1.0
    for p in r["phases"]:
        assert p["hops"]["succeeded"] > 5, p
        t = p["threads"]
        assert t["peak_ceiling"] == verdict.thread_ceiling(t["quiet_outside_pools"], limits)
        assert t["settled_bound"] == verdict.settled_bound(t["quiet_outside_pools"], limits)
        assert 0 < t["quiet_outside_pools"] <= t["before"] <= t["peak"]
        assert t["settled_after_s"] >= 1.0 + hostile.IDLE_MARGIN_S  # after the pools' idle
        assert set(t["pools_settled"]) == {
            "connections",
            "agents",
            "messages",
            "dfrl_bound_notices",
        }
        assert p["accepted_after_s"] is not None and p["accepted_after_s"] >= 0
        assert set(p["cpu_cores"]) == {"phase", "settled"}
        assert p["agents_at_end"] >= 1 and isinstance(p["pass"], bool)
        assert p["pass"] == (p["why"] == [])
    quiet, escapes, loop, frames = r["phases"]
    e = escapes["escapes"]
    assert e["tried"] == 16 and e["tried"] == len(e["attempts"])
    hooks = [a for a in e["attempts"] if a["via"] == "hook"]
    assert len(hooks) == 4 and all(a["verdict"] == "refused" for a in hooks), hooks
    assert all("hook(" in a["error"] for a in hooks), hooks  # the refusal names the hook
    init_loop = next(a for a in e["attempts"] if a["name"] == "init_loop")
    assert init_loop["verdict"] == "stopped", init_loop  # the bounds ended the loop
    assert {(a["via"], a["name"]) for a in e["attempts"]} >= {
        ("agent", "freeze_handler"),
        ("agent", "freeze_findall"),
        ("program", "freeze_init"),
        ("agent", "print_message"),
        ("agent", "portray_goal"),
        ("agent", "double_quotes"),
        ("agent", "argv"),
        ("agent", "other_payload"),
    }
    assert e["ran"] == 0, e["ran_names"]  # the sandbox holds
    assert not any("escapes ran" in w for w in escapes["why"])
    assert loop["attack"]["counts"]["sent"] >= 2 and loop["escapes"] is None
    assert loop["agents_purged"] >= 0
    a = frames["attack"]
    assert a["big"]["sent"] >= 1 and a["flood"]["sent"] > 10
    assert a["flood"].get("reply_existence_error", 0) > 0  # a post to nobody, read and answered
    assert r["pass"] == all(p["pass"] for p in r["phases"])
    assert out.returncode == (0 if r["pass"] else 1)


@pytest.mark.skipif(shutil.which("openssl") is None, reason="needs openssl")
def test_escapes_phase_fails_when_the_target_trusts_the_attacker() -> None:
    # Control: the target installs the attacker's code unchecked (trusted_peers over mutual
    # TLS), so the escapes run, and the phase, the run and the exit status must say so.
    r, out = _hostile("--attacks", "escapes", "--trust-attacker", *AUTH_SHORT)
    quiet, escapes = r["phases"]
    assert quiet["hops"]["succeeded"] > 5, f"no TLS hop: {quiet['hops']['fail_examples']}"
    e = escapes["escapes"]
    ran = {(a["via"], a["name"]) for a in e["attempts"] if a["ran"]}
    assert {
        ("agent", "freeze_handler"),
        ("agent", "freeze_findall"),
        ("agent", "argv"),
        ("agent", "other_payload"),
        ("program", "freeze_init"),
    } <= ran, e
    argv = next(a for a in e["attempts"] if a["name"] == "argv")
    assert argv["reported"] and argv["leaked_token"]  # the target's argv holds its token
    assert any("escapes ran" in w for w in escapes["why"])
    assert escapes["pass"] is False and r["pass"] is False and out.returncode == 1


def _phase(**over) -> dict:
    """A phase that meets every target (quiet p90 10 ms); ``over`` replaces parts of it."""
    p = {
        "hops": {"succeeded": 50, "failed": 0, "unfinished": 0, "hop_p90_ms": 20.0},
        "p90_ratio": 2.0,
        "rss_mb": {"delta": 10.0},
        "accepted_after_s": 0.1,
        "threads": {
            "peak": 60,
            "peak_ceiling": 345,
            "settled": 30,
            "settled_bound": 37,
            "settled_after_s": 6.0,
            "pools_settled": {},
        },
        "cpu_cores": {"settled": 0.05},
        "escapes": None,
        "peer_agent_stopped": [],
    }
    for k, v in over.items():
        p[k] = p[k] | v if isinstance(v, dict) else v
    return p


QUIET = {"cpu_cores": {"phase": 0.05}}


def test_thread_bounds_follow_the_nodes_limits_by_hand() -> None:
    limits = {"max_connections": 64, "max_agents": 100, "connection_workers_max": 128}
    # 7 outside the pools + 128 connection workers + 100 agents + 100 messages + 2 notices + 8
    assert verdict.thread_ceiling(7, limits) == 345
    # 7 + 8 (connections) + 8 (agents) + 8 (messages) + 2 (notices, at most 2) + 4
    assert verdict.settled_bound(7, limits) == 37
    small = {"max_connections": 2, "max_agents": 3, "connection_workers_max": 16}
    assert verdict.settled_bound(5, small) == 5 + 8 + 3 + 3 + 2 + 4


def test_each_criterion_can_fail() -> None:
    assert verdict.misses(_phase(), QUIET) == []
    cases = {
        "threads 6.0 s after": _phase(threads={"settled": 38}),
        "peak of 345 threads": _phase(threads={"peak": 345}),
        "no ordinary agent accepted": _phase(accepted_after_s=None),
        "within 20 s": _phase(accepted_after_s=20.5),
        "stopped the peer's ordinary agent": _phase(peer_agent_stopped=["agent ... stopped"]),
        "RSS grew by 50.1 MB": _phase(rss_mb={"delta": 50.1}),
        "p90 10.0x": _phase(p90_ratio=10.0),
        "CPU 0.31 cores": _phase(cpu_cores={"settled": 0.31}),
        "1 hops failed": _phase(hops={"failed": 1}),
    }
    for needle, p in cases.items():
        why = verdict.misses(p, QUIET)
        assert len(why) == 1 and needle in why[0], (needle, why)


def test_settled_threads_fail_when_warm_pools_are_not_allowed(monkeypatch) -> None:
    # Control on real processes: with no idle worker allowed to stay warm and no slack, the
    # pool workers that the clone bomb's agents needed stay in the settled count, and the
    # phase fails on threads, naming the pools.
    monkeypatch.setattr(verdict, "KEEP_WARM", 0)
    monkeypatch.setattr(verdict, "SETTLED_SLACK", 0)
    r = hostile.run(
        hostile.HostileConfig(
            duration_s=3, settle_s=0.5, pool_idle_s=1, threads_wait_s=1, wave_s=2
        ),
        ("clone",),
    )
    quiet, clone = r["phases"]
    assert clone["threads"]["settled_bound"] == clone["threads"]["quiet_outside_pools"]
    assert any("threads" in w and "pools" in w for w in clone["why"]), clone["why"]
    assert clone["pass"] is False and r["pass"] is False
