"""``dfrl bench hostile`` on a small budget: real ``swipl`` nodes, real attack sockets."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest

from dfrl.experiments.bench.hostile_attacks import (FRAME_KINDS, PRE_AUTH_LIMIT, frame_header,
                                                   hostile_frame, outcome_of)
from dfrl.experiments.bench.hostile_auth_attacks import escape_results
from dfrl.platform_pl import PLATFORM_DIR

pytestmark = pytest.mark.skipif(shutil.which("swipl") is None, reason="needs swipl")


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
    out = subprocess.run(["swipl", "-q", "-g", f"use_module('{PLATFORM_DIR / 'node.pl'}')",
                          "-g", "node:option_default(max_text_frame_size, B), write(B)",
                          "-t", "halt"], capture_output=True, text=True, timeout=30)
    assert out.stdout.strip() == str(PRE_AUTH_LIMIT), out.stderr


def test_small_hostile_benchmark_keeps_hops_succeeding() -> None:
    out = subprocess.run([sys.executable, "-m", "dfrl", "bench", "hostile", "--slowloris", "10",
                          "--flood", "50", "--frames", "6", "--frame-size", "200000",
                          "--duration", "4", "--settle", "1", "--threads-wait", "3",
                          "--attacks", "slowloris", "flood", "frames", "--json"],
                         capture_output=True, text=True, timeout=60)
    r = json.loads(out.stdout)
    assert [p["phase"] for p in r["phases"]] == ["quiet", "slowloris", "flood", "frames"]
    for p in r["phases"]:
        h = p["hops"]
        assert h["succeeded"] > 10 and h["failed"] == 0 and h["unfinished"] == 0, p
        assert h["attempted"] == h["succeeded"]
        assert 0 < h["hop_median_ms"] <= h["hop_p90_ms"]
        assert set(p["rss_mb"]) == {"before", "after", "peak", "delta"}
        assert isinstance(p["pass"], bool)
    quiet, slow, flood, frames = r["phases"]
    assert quiet["attack"] is None and quiet["p90_ratio"] is None
    assert slow["attack"]["opened"] >= 10 and flood["attack"]["opened"] >= 50
    assert flood["attack"]["closed_by_node"] > 0           # 50 > the 32 unauthenticated slots
    assert frames["attack"]["rejected"] > 0
    assert frames["attack"]["reject_reasons"].get("too_large", 0) > 0
    assert frames["attack"]["reject_reasons"].get("too_deep", 0) > 0
    assert set(frames["attack"]["frames_by_kind"]) == set(FRAME_KINDS)
    assert r["pass"] == all(p["pass"] for p in r["phases"])
    assert out.returncode == (0 if r["pass"] else 1), out.stderr[-2000:]


def _hostile(*args: str, timeout: float = 60) -> tuple[dict, subprocess.CompletedProcess]:
    out = subprocess.run([sys.executable, "-m", "dfrl", "bench", "hostile", *args, "--json"],
                         capture_output=True, text=True, timeout=timeout)
    assert out.stdout.startswith("{"), out.stderr[-3000:]
    return json.loads(out.stdout), out


def test_escape_results_decide_ran_from_markers_reports_and_the_flag(tmp_path) -> None:
    marker = tmp_path / "agent_freeze_handler"
    marker.touch()
    attempts = [
        {"name": "freeze_handler", "via": "agent", "verdict": "accepted", "marker": str(marker),
         "reported": False, "carried": None},
        {"name": "argv", "via": "agent", "verdict": "accepted", "marker": str(tmp_path / "x"),
         "reported": True, "carried": "[target,'4243']"},
        {"name": "other_payload", "via": "agent", "verdict": "refused",
         "marker": str(tmp_path / "y"), "reported": False, "carried": None, "error": "e"},
        {"name": "double_quotes", "via": "program", "verdict": "error",
         "marker": str(tmp_path / "z"), "reported": False, "carried": None},
    ]
    e = escape_results(attempts, 4243, "codes", "atom")
    assert [a["ran"] for a in e["attempts"]] == [True, True, False, True]
    assert e["attempts"][1]["leaked_token"] is True
    assert (e["tried"], e["refused"], e["accepted"], e["ran"]) == (4, 1, 2, 3)
    assert escape_results(attempts[2:3], 4243, "codes", "codes")["ran"] == 0


AUTH_SHORT = ("--duration", "3", "--settle", "1", "--pool-idle", "1", "--threads-wait", "5",
              "--escape-wait", "2", "--wave-s", "2")


def test_authenticated_phases_have_their_figures_and_no_escape_runs() -> None:
    r, out = _hostile("--attacks", "escapes", "loop", "authframes", "--auth-big-mb", "1",
                      "--auth-flood", "2", *AUTH_SHORT)
    assert [p["phase"] for p in r["phases"]] == ["quiet", "escapes", "loop", "authframes"]
    for p in r["phases"]:
        assert p["hops"]["succeeded"] > 5, p
        assert set(p["threads"]) == {"before", "peak", "after", "back", "waited_s"}
        assert set(p["cpu_cores"]) == {"phase", "settled"}
        assert p["agents_at_end"] >= 1 and isinstance(p["pass"], bool)
    quiet, escapes, loop, frames = r["phases"]
    e = escapes["escapes"]
    assert e["tried"] == 11 and e["tried"] == len(e["attempts"])
    assert {(a["via"], a["name"]) for a in e["attempts"]} >= {
        ("agent", "freeze_handler"), ("agent", "freeze_findall"), ("program", "freeze_init"),
        ("agent", "print_message"), ("agent", "portray_goal"), ("agent", "double_quotes"),
        ("agent", "argv"), ("agent", "other_payload")}
    assert e["ran"] == 0, e["ran_names"]                  # the sandbox holds
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
    assert {("agent", "freeze_handler"), ("agent", "freeze_findall"), ("agent", "argv"),
            ("agent", "other_payload"), ("program", "freeze_init")} <= ran, e
    argv = next(a for a in e["attempts"] if a["name"] == "argv")
    assert argv["reported"] and argv["leaked_token"]       # the target's argv holds its token
    assert any("escapes ran" in w for w in escapes["why"])
    assert escapes["pass"] is False and r["pass"] is False and out.returncode == 1
