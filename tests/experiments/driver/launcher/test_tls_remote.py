"""``dfrl inject --tls DIR`` and ``dfrl join --tls DIR`` (issue 9): acting on a running TLS
experiment from a copy of its results folder, whose ``nodes.json`` records a TLS folder that does
not exist on this host; ``--tls`` names this host's copy of the driver's certificate folder
instead. A bad ``--tls`` folder exits 2 and sends nothing; without ``--tls`` the unusable recorded
folder is reported with where it came from. Real processes, real mutual TLS.

Join comes before inject: an injected method is loaded into the nodes ``nodes.json`` lists at
that moment, so a robot that joins later would not have it.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from dfrl.experiments.tools.certs import init_ca, make_node
from dfrl.experiments.driver.results.agent_log import read_rounds_log
from dfrl.platform_pl import DFRL_AGENT_DIR

from .helpers import diagnose, rounds_csv, run_in_thread, small_config, stop_agents, wait_rounds
from dfrl.experiments.processes import find_swipl

pytestmark = [
    pytest.mark.skipif(find_swipl() is None, reason="needs swipl"),
    pytest.mark.skipif(shutil.which("openssl") is None, reason="needs openssl"),
]

MEDIAN = DFRL_AGENT_DIR / "examples" / "median_method.pl"
AGENT = "fed_qlearning"


def _dfrl(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "dfrl", *args], cwd=cwd, capture_output=True, text=True, timeout=120
    )


def _start_dfrl(*args: str, cwd: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "dfrl", *args],
        cwd=cwd,
        text=True,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )


def test_inject_and_join_with_tls_from_a_copied_results_folder(tmp_path: Path) -> None:
    # Prepare: a TLS run; a copy of its results folder whose nodes.json names a TLS folder
    # that is not on this host, and this host's copy of the driver's certificate folder
    init_ca(tmp_path / "ca")
    node_dir = make_node("local", tmp_path / "ca", tmp_path / "tls-local").directory
    out = tmp_path / "run"
    # a long run (300 rounds, ~4 min), ended by a stop command once the refusals, the join and
    # the inject were done: they take seconds each on a loaded machine, and a run of fixed
    # length (24 s) ended before the inject in 2 of 3 loaded suite runs
    cfg = small_config(iterations=45000, respite=150, rtf=12.0, timeout_s=400)
    t, box = run_in_thread(cfg, out, tls=node_dir)
    wait_rounds(out, AGENT, 2)
    copied = tmp_path / "copied"
    copied.mkdir()
    gone = tmp_path / "other-host" / "tls-local"

    def copy_results() -> None:
        info = json.loads((out / "nodes.json").read_text(encoding="utf-8"))
        assert info["tls"] == str(node_dir.resolve())
        (copied / "nodes.json").write_text(json.dumps({**info, "tls": str(gone)}), encoding="utf-8")
        shutil.copy2(out / "secret.token", copied)  # the run's token (mode 0600) goes along

    copy_results()
    driver = shutil.copytree(node_dir, tmp_path / "driver-tls")
    bad = tmp_path / "bad-tls"
    bad.mkdir()
    shutil.copy(node_dir / "ca.crt", bad)
    inject = ["inject", str(copied), "--program", str(MEDIAN), "--method", "median"]
    # r3 lives 6,000 iterations (~30 s at rtf 12): with 600 it could end (3 s) before the
    # inject below reached its node, which then refused the connection (2 loaded suite runs)
    join = ["join", str(copied), "--robot", "r3", "--arena", "r5", "--iterations", "6000"]
    # Execute (the four refusals at once, the run goes on meanwhile)
    refusals = {}
    for command in (inject, join):
        refusals[command[0], True] = _start_dfrl(*command, "--tls", str(bad), cwd=tmp_path)
        refusals[command[0], False] = _start_dfrl(*command, cwd=tmp_path)
    # Assert: a bad --tls folder: exit 2, located, nothing sent; without --tls: the recorded
    # folder is unusable here, and the message says so
    for (name, with_tls), proc in refusals.items():
        stdout, stderr = proc.communicate(timeout=120)
        if with_tls:
            assert proc.returncode == 2, stdout + stderr
            assert (
                f"dfrl {name}: --tls: {bad} is not a node TLS directory: missing node.crt, node.key"
                in stderr
                and "nothing was sent" in stderr
            ), stderr
        else:
            assert proc.returncode == 1, stdout + stderr
            assert (
                f"{copied / 'nodes.json'} names the TLS folder {gone}, not usable here" in stderr
                and "--tls DIR" in stderr
            ), stderr
    assert read_rounds_log(out / f"rounds_{AGENT}.log", AGENT).controls == []
    # ... with --tls DIR: the robot joins; then (from a fresh copy that lists r3, so that the
    # method reaches its node too) the method is applied
    done = _dfrl(*join, "--tls", str(driver), cwd=tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.startswith("robot r3 runs at "), done.stdout
    copy_results()
    done = _dfrl(*inject, "--tls", str(driver), cwd=tmp_path)
    assert done.returncode == 0, done.stdout + done.stderr
    assert f"method median applied by {AGENT}" in done.stdout
    stop_agents(out)
    t.join(timeout=180)
    assert not t.is_alive(), "the run did not end within 180 s of its stop command"
    res = box.get("res") or pytest.fail(f"run failed: {box.get('exc')!r}")
    assert res.ok, diagnose(out)
    controls = read_rounds_log(out / f"rounds_{AGENT}.log", AGENT).controls
    assert [c.status for c in controls if c.command.startswith("method")] == ["applied"]
    rows = rounds_csv(out)
    methods = [r["method"] for r in rows]
    first = methods.index("median")
    assert set(methods[:first]) == {"average"} and set(methods[first:]) == {"median"}
    visited = [r["visited"] for r in rows]
    assert visited[0] == "r1 r2" and "r1 r2 r3" in visited
