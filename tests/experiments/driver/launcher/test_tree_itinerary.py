"""A ``"itinerary": "tree"`` run on real processes: the agent clones itself over the robots
each round, and every robot ends each round with the table a chain run gives."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from dfrl.experiments.driver.config import ConfigError, ExperimentConfig
from dfrl.experiments.driver.launcher import run, spawn
from dfrl.experiments.processes import find_swipl

from .helpers import diagnose, rounds_csv, small_config

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")

ROBOTS = ["r1", "r2", "r3", "r4", "r5"]


def test_tree_rounds_equal_the_chain_rounds(tmp_path: Path) -> None:
    # Prepare: five robots in different arenas visit their state-actions unequally, so
    # visit_average weights them differently: a merge that averaged the subtrees' averages
    # (r1; r2 r4 r5; r3) would give other tables than the chain's one walk
    kw = dict(iterations=300, respite=100, method="visit_average")
    chain = small_config(5, **kw)
    tree = small_config(5, itinerary="tree", fanout=2, **kw)
    # Execute
    res_chain = run(chain, tmp_path / "chain", progress=None)
    res_tree = run(tree, tmp_path / "tree", progress=None)
    # Assert
    assert res_chain.ok and res_tree.ok, diagnose(tmp_path / "chain", tmp_path / "tree")
    rows_chain, rows_tree = rounds_csv(tmp_path / "chain"), rounds_csv(tmp_path / "tree")
    assert [r["round"] for r in rows_tree] == ["1", "2", "3"]
    for rc, rt in zip(rows_chain, rows_tree, strict=True):
        assert rt["all_equal"] == "true" and rt["visited"] == " ".join(ROBOTS), rt
        assert rt["skipped"] == "" and int(rt["hops"]) == 4  # a clone per robot but r1
        for robot in ROBOTS:
            assert rt[f"digest_{robot}"] == rc[f"digest_{robot}"], (rt["round"], robot)
    assert len({r["digest_r1"] for r in rows_tree}) == 3  # the tables moved on
    # sync mode, same seed: the same curves whichever itinerary
    assert (tmp_path / "chain/metrics.csv").read_bytes() == (
        tmp_path / "tree/metrics.csv"
    ).read_bytes()
    launch = json.loads((tmp_path / "tree/launch_fed_qlearning.json").read_text())
    assert launch["itinerary_kind"] == "tree" and launch["fanout"] == 2
    log = [
        json.loads(line)
        for line in (tmp_path / "tree/rounds_fed_qlearning.log").read_text().splitlines()
    ]
    assert {e.get("itinerary") for e in log if e["event"] == "round"} == {"tree"}
    # the control of the control: the chain's launch plan names no itinerary kind
    assert "itinerary_kind" not in json.loads(
        (tmp_path / "chain/launch_fed_qlearning.json").read_text()
    )


@pytest.mark.parametrize(
    "bad, message",
    [
        ({"itinerary": "ring"}, "itinerary: unknown itinerary 'ring'; known: chain, tree"),
        ({"itinerary": "tree", "fanout": 1}, "fanout: must be >= 2, got 1"),
    ],
)
def test_bad_itinerary_is_refused_where_it_is(bad: dict, message: str) -> None:
    with pytest.raises(ConfigError, match=message.replace("(", r"\(")):
        ExperimentConfig.from_dict({"robots": [{"id": "r1", "arena": "r1"}], **bad})


@pytest.mark.slow
def test_scale_bench_compares_the_itineraries_with_a_delay() -> None:
    # dfrl bench scale with both itineraries behind a 20 ms proxy on every node: both give
    # identical tables every round, and the delay shows in the chain's rounds (the control
    # that the proxies are really in the way): 2(N-1) hops of at least 2 x 20 ms each
    import subprocess
    import sys

    out = subprocess.run(
        [
            sys.executable,
            "-m",
            "dfrl",
            "bench",
            "scale",
            "--robots",
            "4",
            "--iterations",
            "60",
            "--respite",
            "20",
            "--itinerary",
            "chain",
            "tree",
            "--delay-ms",
            "20",
            "--json",
        ],
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    r = json.loads(out.stdout)
    assert [(p["itinerary"], p["delay_ms"]) for p in r["points"]] == [
        ("chain", 20.0),
        ("tree", 20.0),
    ]
    assert all(p["identical_every_round"] and p["rounds"] == 3 for p in r["points"])
    chain = r["points"][0]
    assert chain["round_median_ms"] > 6 * 2 * 20
    assert r["compare"][0]["robots"] == 4 and r["compare"][0]["tree_over_chain"] > 0


@pytest.mark.parametrize("limited", [False, True], ids=["tree-clone-limit", "control"])
def test_many_fast_tree_rounds_skip_nobody(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, limited: bool
) -> None:
    # 60 rounds of 3 robots as fast as they go: every copy is a clone at the parent's node, and
    # the platform's default admits 60 clones a minute. The control keeps that default for the
    # robots' nodes (as before the run set its own): rounds must then skip robots for clones.
    if limited:
        monkeypatch.setattr(spawn, "clone_limit", lambda c: None)
    cfg = small_config(3, iterations=600, respite=10, itinerary="tree", fanout=2)
    res = run(cfg, tmp_path / "out", progress=None)
    rows = rounds_csv(tmp_path / "out")
    refused = [r for r in rows if "clones" in r["skipped"]]
    if limited:
        assert refused, "the control skipped nobody: the test could not see the limit"
        return
    assert res.ok and len(rows) == 60 and not refused, diagnose(tmp_path / "out")
    assert all(r["all_equal"] == "true" and r["skipped"] == "" for r in rows)
