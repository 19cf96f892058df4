"""The view server on a real run: the event stream carries every round and hop of the
rounds log, in order, live and when replayed; the page and its assets are served."""

from __future__ import annotations

import json
import urllib.request
from pathlib import Path

import pytest

from dfrl.experiments.driver.results.agent_log import read_rounds_log
from dfrl.experiments.tools.view import start_view

from ...driver.launcher.helpers import run_in_thread, small_config
from .helpers import canonical, hop_order, read_stream, write_run
from dfrl.experiments.processes import find_swipl

needs_swipl = pytest.mark.skipif(find_swipl() is None, reason="needs swipl")


def _check_stream(events: list[dict], out: Path, agent: str = "fed_qlearning") -> None:
    log = read_rounds_log(out / f"rounds_{agent}.log", agent)
    assert len(log.rounds) == 4
    assert [e["seq"] for e in events] == list(range(len(events)))
    rounds = [e for e in events if e["kind"] == "round" and e["agent"] == agent]
    assert [r["round"] for r in rounds] == [r.round for r in log.rounds]
    for ev, rec in zip(rounds, log.rounds):
        assert ev["visited"] == list(rec.visited) and ev["method"] == rec.method
        assert hop_order(events, agent, rec.round) == canonical(list(rec.visited))
        hops = [e["seq"] for e in events if e["kind"] == "hop" and e["round"] == rec.round]
        assert max(hops) < ev["seq"]
    shares = [e for e in events if e["kind"] == "share"]
    assert len(shares) == 8  # 2 robots x 4 rounds
    for rid in ("r1", "r2"):
        pts = [
            p for e in events if e["kind"] == "metrics" and e["robot"] == rid for p in e["points"]
        ]
        assert pts[-1][0] == 200
    assert events[-1]["kind"] in ("run_end", "robot_state")


@needs_swipl
def test_live_stream_of_a_real_run_and_its_replay(tmp_path: Path) -> None:
    out = tmp_path / "run"
    with start_view(out, fresh=True) as view:
        thread, box = run_in_thread(small_config(), out)
        live = read_stream(view.url, lambda ev: any(e["kind"] == "run_end" for e in ev), 90)
        thread.join(60)
        assert box.get("res") is not None and box["res"].ok, box
        _check_stream(live, out)
        # a client arriving later gets the same history
        again = read_stream(view.url, lambda ev: len(ev) >= len(live), 10)
        assert [e["seq"] for e in again[: len(live)]] == [e["seq"] for e in live]
        assert [e["kind"] for e in again[: len(live)]] == [e["kind"] for e in live]
    # the finished run, served afresh (dfrl view): same rounds and hops, in order
    with start_view(out) as view:
        replay = read_stream(view.url, lambda ev: any(e["kind"] == "run_end" for e in ev), 10)
    _check_stream(replay, out)


def test_page_assets_json_and_resume(tmp_path: Path) -> None:
    write_run(tmp_path)
    with start_view(tmp_path, poll_s=0.05) as view:
        assert view.url.startswith("http://127.0.0.1:")
        page = urllib.request.urlopen(view.url, timeout=5).read().decode()
        assert 'id="network"' in page and "/static/view.js" in page
        for name in ("view.js", "view.css"):
            with urllib.request.urlopen(view.url + "static/" + name, timeout=5) as resp:
                assert resp.status == 200 and len(resp.read()) > 1000
        with pytest.raises(urllib.error.HTTPError):
            urllib.request.urlopen(view.url + "static/../server.py", timeout=5)
        evs = read_stream(view.url, lambda ev: len(ev) >= 7, 5)
        got = json.loads(urllib.request.urlopen(view.url + "events.json?from=2", timeout=5).read())
        assert got[0]["seq"] == 2 and [e["seq"] for e in got] == [e["seq"] for e in evs[2:]]
        # EventSource's reconnection: Last-Event-ID resumes after that event
        req = urllib.request.Request(view.url + "events", headers={"Last-Event-ID": "4"})
        with urllib.request.urlopen(req, timeout=5) as resp:
            line = resp.readline()
            while not line.startswith(b"data: "):  # retry:, blank, id: lines first
                line = resp.readline()
        assert json.loads(line[6:])[0]["seq"] == 5
    assert view.closed


def test_cli_view_refuses_a_folder_without_config(tmp_path: Path) -> None:
    from dfrl.experiments.cli import view as cli_view

    import argparse

    ns = argparse.Namespace(results_dir=str(tmp_path), host="127.0.0.1", port=0)
    assert cli_view.cmd_view(ns) == 2
