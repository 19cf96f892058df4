"""``dfrl bench migrate`` on real processes, tiny budget: the hop, the naive text hop beside it,
and the step trace."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from dfrl.experiments.tools.bench import migrate
from dfrl.experiments.processes import find_swipl

pytestmark = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")


def test_migrate_json_has_the_naive_hop_and_its_ratio(capsys: pytest.CaptureFixture[str]) -> None:
    from dfrl.experiments.cli import main

    assert (
        main(
            ["bench", "migrate", "--floats", "0", "20000", "--hops", "3", "--warmup", "1", "--json"]
        )
        == 0
    )
    rows = [json.loads(line) for line in capsys.readouterr().out.splitlines() if line.strip()]
    assert [r["floats"] for r in rows] == [0, 20000]
    for r in rows:
        assert r["hops"] == 3
        assert 0 < r["median_ms"] < 5000
        assert 0 < r["naive_median_ms"] < 5000
        assert r["naive_ratio"] == pytest.approx(r["median_ms"] / r["naive_median_ms"])
    # writing 20,000 floats as text and parsing them back costs more than an empty record (some
    # 15 ms against 0.2 ms: 2,000 floats, about 1 ms, lost to an empty record once on a busy machine)
    assert rows[1]["naive_median_ms"] > rows[0]["naive_median_ms"]


def test_migrate_text_output_shows_the_ratio(capsys: pytest.CaptureFixture[str]) -> None:
    from dfrl.experiments.cli import main

    assert main(["bench", "migrate", "--floats", "100", "--hops", "2", "--warmup", "0"]) == 0
    out = capsys.readouterr().out
    assert "naive text hop" in out and "ratio" in out


def test_cpu_per_hop_from_hand_made_stamps() -> None:
    # port 1 at arrivals 0, 2, 4; port 2 at 1, 3, 5 (seconds of CPU so far)
    stamps = [[1, 0.0], [2, 0.0], [1, 0.010], [2, 0.004], [1, 0.020], [2, 0.008]]
    # port 1: 20 ms over 4 hops, port 2: 8 ms over 4 hops
    assert migrate.cpu_per_hop(stamps, 0) == pytest.approx(5.0 + 2.0)
    # after 2 warm-up hops: port 1 10 ms over 2 hops, port 2 4 ms over 2 hops
    assert migrate.cpu_per_hop(stamps, 2) == pytest.approx(5.0 + 2.0)
    # control: a process with one stamp in the window gives no figure
    assert migrate.cpu_per_hop(stamps, 4) is None
    assert migrate.cpu_per_hop([], 0) is None


def test_run_reports_cpu_per_hop_that_grows_with_the_payload() -> None:
    small = migrate.run(0, 6, warmup=1, naive=False, payload="list")
    large = migrate.run(50000, 6, warmup=1, naive=False, payload="list")
    assert small.cpu_ms_per_hop is not None and large.cpu_ms_per_hop is not None
    assert 0 < small.cpu_ms_per_hop < 1000
    # serialising, sending, reading and compiling 50,000 floats costs CPU an empty record does not
    assert large.cpu_ms_per_hop > small.cpu_ms_per_hop + 2
    assert large.payload == "list"


def test_packed_payload_costs_less_than_a_list() -> None:
    # the same 50,000 floats, packed as the dFRL agent carries tables: a string is serialised,
    # sent and asserted as one block; the list (the control, same run) is compiled float by float
    packed = migrate.run(50000, 6, warmup=1, naive=False, payload="packed")
    listed = migrate.run(50000, 6, warmup=1, naive=False, payload="list")
    assert packed.payload == "packed" and listed.payload == "list"
    assert packed.native is True  # setup.sh built the foreign libraries
    assert packed.cpu_ms_per_hop is not None and listed.cpu_ms_per_hop is not None
    assert packed.cpu_ms_per_hop * 2 < listed.cpu_ms_per_hop, (packed, listed)


def test_run_refuses_an_unknown_payload() -> None:
    with pytest.raises(ValueError, match="payload"):
        migrate.run(10, 2, payload="tuple")


def test_run_without_naive_leaves_the_fields_empty() -> None:
    r = migrate.run(0, 2, warmup=0, naive=False)
    assert r.naive_median_ms is None and r.naive_ratio is None


def test_phase_breakdown_orders_the_steps_of_a_hand_over(tmp_path: Path) -> None:
    r = migrate.run(500, 4, warmup=1, naive=False, trace_dir=tmp_path)
    assert (tmp_path / "home.jsonl").exists() and (tmp_path / "peer.jsonl").exists()
    phases = migrate.phase_breakdown(tmp_path, warmup=1)
    by = {(p.step, p.side): p for p in phases}
    for key in [
        ("export", "source"),
        ("write(transfer)", "source"),
        ("read(transfer)", "destination"),
        ("check", "destination"),
        ("install", "destination"),
        ("custody_commit", "source"),
        ("write(commit)", "source"),
        ("activate", "destination"),
        ("agent_run", "destination"),
    ]:
        assert key in by, (key, sorted(by))
    order = [
        by[k].median_start_ms
        for k in [
            ("export", "source"),
            ("install", "destination"),
            ("custody_commit", "source"),
            ("activate", "destination"),
        ]
    ]
    assert order == sorted(order)
    # the handler starts within the hop the agent measured (same clock, one process each side)
    assert by[("agent_run", "destination")].median_start_ms <= r.max_ms + 1.0
    assert all(p.median_ms >= 0 for p in phases)


def test_phase_breakdown_of_an_empty_folder_is_empty(tmp_path: Path) -> None:
    assert migrate.phase_breakdown(tmp_path) == []


def test_migrate_tls_prints_its_cost_beside_the_naive_hop(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from dfrl.experiments.cli import main
    from dfrl.experiments.tools import certs

    certs.init_ca(tmp_path / "ca")
    certs.make_node("bench", tmp_path / "ca", tmp_path / "node")
    assert (
        main(
            [
                "bench",
                "migrate",
                "--floats",
                "100",
                "--hops",
                "2",
                "--warmup",
                "0",
                "--rounds",
                "2",
                "--tls",
                str(tmp_path / "node"),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "TLS cost" in out and "naive text hop" in out and "ratio" in out
    cost = float(out.split("TLS cost")[1].split("%")[0])
    assert -100 < cost < 10000
    # two rounds: each round's cost, and the interval of their mean around that mean
    rounds = out.split("  rounds ")[1].split(";")[0].split(", ")
    assert len(rounds) == 2 and all(r.endswith("%") for r in rounds)
    low, high = (
        float(x.rstrip("%")) for x in out.split("95% interval ")[1].split("  ")[0].split(" to ")
    )
    mean = float(out.split("; mean ")[1].split("%")[0])
    assert low <= mean <= high
    assert "records: straight to the socket" in out  # setup.sh built native/tls_direct.c
    # control: a folder without the node's files is refused before any process starts
    assert (
        main(["bench", "migrate", "--floats", "100", "--hops", "2", "--tls", str(tmp_path / "ca")])
        == 2
    )


def test_against_another_checkout_alternates_their_hops(tmp_path: Path) -> None:
    # the other checkout: a copy of this one's program whose agent records every hop as
    # 1000 ms, so the test sees that the other side's runs used the other program
    root = Path(migrate.SCRIPT).parents[3]
    other = tmp_path / "other"
    (other / "experiments" / "tools" / "bench").mkdir(parents=True)
    text = migrate.SCRIPT.read_text().replace(
        "'../../../platform_pl/", f"'{root.as_posix()}/platform_pl/"
    )
    (other / "experiments" / "tools" / "bench" / "bench_migrate.pl").write_text(text)
    handler = (migrate.SCRIPT.parent / "bench_hop_handler.pl").read_text()
    assert "Ms is (Now - T0) * 1000," in handler
    (other / "experiments" / "tools" / "bench" / "bench_hop_handler.pl").write_text(
        handler.replace("Ms is (Now - T0) * 1000,", "Ms is 1000.0 + 0 * (Now - T0),")
    )
    (other / "experiments" / "tools" / "bench" / "step_trace.pl").write_text(
        (migrate.SCRIPT.parent / "step_trace.pl").read_text()
    )
    cmp = migrate.compare_checkouts(100, 2, other, runs=2, warmup=0)
    assert cmp.runs == 2 and len(cmp.this_runs_ms) == 2 and len(cmp.other_runs_ms) == 2
    assert cmp.other_runs_ms == [1000.0, 1000.0]
    assert all(0 < ms < 1000 for ms in cmp.this_runs_ms)
    assert cmp.this_over_other == pytest.approx(cmp.this_median_ms / cmp.other_median_ms)
    # run by run: run i of this checkout against run i of the other
    assert cmp.pairs is not None
    assert cmp.pairs.ratios == pytest.approx([a / 1000.0 for a in cmp.this_runs_ms])
    assert cmp.pairs.low <= cmp.pairs.mean <= cmp.pairs.high
    assert cmp.this_naive_ratio is not None and cmp.other_naive_ratio is not None
    # control: a folder that is no checkout is refused before any process starts
    with pytest.raises(ValueError, match="bench_migrate.pl"):
        migrate.compare_checkouts(100, 2, tmp_path / "nothing")


def test_against_on_the_command_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from dfrl.experiments.cli import main

    root = Path(migrate.SCRIPT).parents[3]
    assert (
        main(
            [
                "bench",
                "migrate",
                "--floats",
                "0",
                "--hops",
                "2",
                "--warmup",
                "0",
                "--rounds",
                "1",
                "--against",
                str(root),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "this/against" in out and "naive ratio" in out
    assert (
        main(["bench", "migrate", "--floats", "0", "--hops", "2", "--against", str(tmp_path)]) == 2
    )


def test_hop_figures_reads_arrival_lines_and_the_older_format() -> None:
    new = (
        "NATIVE true true true\nARRIVAL - 10 0.5\nARRIVAL 1.5 20 0.7\nARRIVAL 2.5 10 0.9\n"
        "ARRIVAL - 20 1.1\nARRIVALS_END\n"
    )
    assert migrate._hop_figures(new) == ([1.5, 2.5], [[10, 0.5], [20, 0.7], [10, 0.9], [20, 1.1]])
    old = "CPU_S [[10, 0.5], [20, 0.7]]\nLATENCIES_MS [1.5]\n"  # a checkout before ARRIVAL
    assert migrate._hop_figures(old) == ([1.5], [[10, 0.5], [20, 0.7]])
    # control: output that ended before its figures did is no result
    assert migrate._hop_figures(new.replace("ARRIVALS_END\n", "")) is None


def test_a_long_run_reports_every_hop_across_batches() -> None:
    # 150 hops: home prints the carried stamps in batches (at most 64 carried), so every hop
    # is reported once, in order, and the CPU figure has a stamp for every arrival
    r = migrate.run(0, 150, warmup=0, naive=False)
    assert r.hops == 150
    assert r.cpu_ms_per_hop is not None and r.cpu_ms_per_hop > 0


def test_paired_ratio_is_a_t_interval_on_the_logs() -> None:
    import math

    from scipy import stats

    tls = [1.10, 1.32, 1.21, 1.15]
    plain = [1.00, 1.10, 1.00, 1.05]
    r = migrate.paired_ratio(tls, plain)
    logs = [math.log(a / b) for a, b in zip(tls, plain)]
    m = sum(logs) / 4
    se = math.sqrt(sum((x - m) ** 2 for x in logs) / 3 / 4)
    half = stats.t.ppf(0.975, 3) * se
    assert r.ratios == pytest.approx([a / b for a, b in zip(tls, plain)])
    assert r.mean == pytest.approx(math.exp(m))
    assert (r.low, r.high) == pytest.approx((math.exp(m - half), math.exp(m + half)))
    # control: the other way round is the reciprocal, interval included
    back = migrate.paired_ratio(plain, tls)
    assert back.mean == pytest.approx(1 / r.mean)
    assert (back.low, back.high) == pytest.approx((1 / r.high, 1 / r.low))
    # identical pairs: no spread; one pair: no interval
    same = migrate.paired_ratio([2.0, 4.0], [1.0, 2.0])
    assert (same.mean, same.low, same.high) == pytest.approx((2.0, 2.0, 2.0))
    one = migrate.paired_ratio([2.0], [1.0])
    assert one.mean == pytest.approx(2.0) and math.isnan(one.low) and math.isnan(one.high)


@pytest.mark.parametrize(
    "a, b, match",
    [
        ([1.0, 2.0], [1.0], "equal counts"),
        ([], [], "no pairs"),
        ([1.0, 0.0], [1.0, 1.0], "positive"),
        ([1.0, float("nan")], [1.0, 1.0], "positive"),
    ],
)
def test_paired_ratio_refuses_bad_runs(a: list[float], b: list[float], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        migrate.paired_ratio(a, b)
