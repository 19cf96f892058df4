"""``dfrl bench hostile`` on a small budget: real ``swipl`` nodes, real attack sockets."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys

import pytest

from dfrl.experiments.bench.hostile_attacks import (FRAME_KINDS, PRE_AUTH_LIMIT, frame_header,
                                                   hostile_frame, outcome_of)
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
                          "--duration", "4", "--settle", "1", "--json"],
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
