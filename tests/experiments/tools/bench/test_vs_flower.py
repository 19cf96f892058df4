"""``dfrl bench vs-flower``: the refusal without Flower, what each size holds, the ratio's
interval, and (with Flower installed) one tiny run on real processes."""

from __future__ import annotations

import importlib.util
import json
import math
import re
from pathlib import Path

import pytest

from dfrl.experiments.cli import main
from dfrl.experiments.processes import find_swipl
from dfrl.experiments.tools.bench import vs_flower

ROOT = Path(__file__).resolve().parents[4]


def test_without_flower_the_command_refuses_naming_the_extra(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    real = importlib.util.find_spec
    monkeypatch.setattr(
        vs_flower.importlib.util,
        "find_spec",
        lambda name, *a: None if name == "flwr" else real(name, *a),
    )
    assert main(["bench", "vs-flower", "--sizes", "243", "--json"]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    assert "Flower is not installed" in captured.err
    assert "pip install 'dfrl[flower]'" in captured.err
    with pytest.raises(RuntimeError, match="dfrl\\[flower\\]"):
        vs_flower.bench((243,), pairs=1, rounds=1, warmup=0)


def test_only_the_benchmarks_flower_process_imports_flwr() -> None:
    importers = sorted(
        str(path.relative_to(ROOT))
        for folder in ("experiments", "pybridge", "robots", "arenas", "platform_pl", "dfrl")
        for path in (ROOT / folder).rglob("*.py")
        if re.search(r"^\s*(import flwr|from flwr)\b", path.read_text(), re.MULTILINE)
    )
    assert importers == ["experiments/tools/bench/flower_peer.py"]


def test_each_size_holds_a_network_or_a_table_of_that_many_floats() -> None:
    assert vs_flower.payload(4931).learner == "dqn"  # the dqn network's layout
    assert vs_flower.payload(771).learner == "linear"
    assert vs_flower.payload(243).shapes == [(81, 3)]  # the paper's table
    assert vs_flower.payload(20000).shapes == [(5000, 4)]
    assert vs_flower.payload(4933).shapes == [(4933, 1)]
    for n in (243, 4931, 20000, 100000, 4933):
        assert sum(math.prod(s) for s in vs_flower.payload(n).shapes) == n
    with pytest.raises(ValueError):
        vs_flower.payload(0)


def test_the_ratio_is_the_geometric_mean_with_a_t_interval_on_the_logs() -> None:
    # pairs (flower_ms, dfrl_ms) with ratios 2 and 8: geometric mean 4; logs ln2, ln8:
    # mean 2 ln2, sd sqrt(2) ln2, se ln2, t(0.975, 1) = 12.706
    ratio, low, high = vs_flower.ratio_interval([(1.0, 2.0), (1.0, 8.0)])
    assert ratio == pytest.approx(4.0)
    assert low == pytest.approx(math.exp(2 * math.log(2) - 12.7062 * math.log(2)), rel=1e-3)
    assert high == pytest.approx(math.exp(2 * math.log(2) + 12.7062 * math.log(2)), rel=1e-3)
    one, no_low, no_high = vs_flower.ratio_interval([(2.0, 3.0)])
    assert one == pytest.approx(1.5) and no_low is None and no_high is None


@pytest.mark.skipif(find_swipl() is None, reason="needs swipl")
def test_one_tiny_run_of_both_sides(capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("flwr")
    argv = ["bench", "vs-flower", "--sizes", "243", "--robots", "3", "--pairs", "1"]
    assert main([*argv, "--rounds", "3", "--warmup", "1", "--json"]) == 0
    r = json.loads(capsys.readouterr().out)
    assert r["benchmark"] == "vs-flower" and r["robots"] == 3 and r["itinerary"] == "chain"
    (e,) = r["sizes"]
    assert e["floats"] == 243 and e["payload"] == "table 81 x 3" and e["pairs"] == 1
    assert e["flower_ms"] > 0 and e["dfrl_ms"] > 0
    ((flower_ms, dfrl_ms),) = e["pair_ms"]
    assert e["ratio"] == pytest.approx(dfrl_ms / flower_ms, rel=1e-3)
    assert e["ratio"] == pytest.approx(e["dfrl_ms"] / e["flower_ms"], rel=1e-3)
    assert e["ratio_low"] is None and e["ratio_high"] is None  # one pair: no interval
    assert e["problems"] == []
