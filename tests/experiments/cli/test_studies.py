"""``dfrl sweep``, the studies' seed options, SIGTERM to ``dfrl paper`` and ``dfrl --version``
from the command line."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

import dfrl
from dfrl.experiments.cli.studies import parse_factor


def _dfrl(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "dfrl", *args], capture_output=True, text=True, timeout=300
    )


def test_version() -> None:
    out = _dfrl("--version")
    assert out.returncode == 0 and out.stdout.strip() == f"dfrl {dfrl.__version__}"


def test_factor_syntax() -> None:
    assert parse_factor("learner.alpha=0.1;0.2") == ("learner.alpha", [0.1, 0.2])
    assert parse_factor('learner.epsilon={"kind":"constant"}') == (
        "learner.epsilon",
        [{"kind": "constant"}],
    )
    assert parse_factor("discretisation.grouping=five") == ("discretisation.grouping", ["five"])


def test_sweep_command_writes_its_table(tmp_path: Path) -> None:
    out = _dfrl(
        "sweep",
        "--set",
        "learner.alpha=0.5",
        "--iterations",
        "300",
        "--seeds",
        "1",
        "2",
        "--eval-steps",
        "100",
        "--held-out",
        "h1",
        "--out",
        str(tmp_path),
    )
    assert out.returncode == 0, out.stderr
    data = json.loads((tmp_path / "sweep.json").read_text())
    assert [d["setting"] for d in data] == ["base", "learner.alpha=0.5"]
    assert len(data[0]["runs"]) == 2
    assert (tmp_path / "sweep.md").read_text().startswith("| setting | score |")
    assert json.loads((tmp_path / "provenance.json").read_text())["command"][:2] == [
        "dfrl",
        "sweep",
    ]
    bad = _dfrl("sweep", "--set", "learner.nope=1", "--iterations", "300", "--seed", "1")
    assert bad.returncode == 2 and "learner.nope" in bad.stderr


def test_seed_options_are_unambiguous() -> None:
    import argparse

    from dfrl.experiments.cli import build_parser
    from dfrl.experiments.cli.seeds import chosen_seeds

    parser = build_parser()
    seeds = lambda *a: chosen_seeds(parser.parse_args(["paper", *a]))  # noqa: E731
    assert seeds() == (1, 2, 3, 4, 5)  # the default count
    assert seeds("--n-seeds", "3") == (1, 2, 3)
    assert seeds("--seeds", "4", "9") == (4, 9)
    assert seeds("--seed", "5") == (5,)
    with pytest.raises(ValueError, match="--seeds 5 is ambiguous: write --n-seeds 5 .* --seed 5"):
        seeds("--seeds", "5")
    with pytest.raises(ValueError, match="given twice"):
        seeds("--seeds", "2", "2")
    with pytest.raises(ValueError, match="at least 1"):
        seeds("--n-seeds", "0")
    with pytest.raises(SystemExit):  # one way at a time
        parser.parse_args(["paper", "--seeds", "1", "2", "--n-seeds", "2"])
    assert isinstance(parser, argparse.ArgumentParser)


def test_ambiguous_seeds_refused_by_every_study(tmp_path: Path) -> None:
    for cmd in (["paper", "--out", str(tmp_path / "p")], ["speedup"], ["sweep"]):
        out = _dfrl(*cmd, "--seeds", "5")
        assert out.returncode == 2 and "--seeds 5 is ambiguous" in out.stderr, (cmd, out.stderr)
    assert not (tmp_path / "p").exists()  # nothing started


@pytest.mark.slow
@pytest.mark.parametrize("how, started", [("--driver", "nodes.json"), ("", "config.json")])
def test_sigterm_stops_the_whole_paper(tmp_path: Path, how: str, started: str) -> None:
    """Through the driver (robot processes up) and with in-process replicas (the first one
    writing its folder): SIGTERM stops the study, not only the run."""
    import signal
    import time

    from dfrl.experiments.processes import find_swipl

    if find_swipl() is None:
        pytest.skip("needs swipl")
    # Prepare: one seed, five federated runs one after another
    out = tmp_path / "paper"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "dfrl",
            "paper",
            "--out",
            str(out),
            "--seed",
            "1",
            "--iterations",
            "3000",
            "--respite",
            "500",
            "--eval-points",
            "1",
            "--eval-steps",
            "50",
            "--jobs",
            "1",
        ]
        + ([how] if how else []),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        # Execute: SIGTERM once the first federated run has its robots up
        first = out / "seed1" / "paper_qlearning_average" / started
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None and not first.is_file():
            time.sleep(0.2)
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(signal.SIGTERM)
        _, stderr = proc.communicate(timeout=90)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    # Assert: the study stopped (not just that run), said so, and started no other run
    assert proc.returncode == 130, stderr
    assert "dfrl paper: stopped" in stderr and "--skip-existing" in stderr
    assert not (out / "seed1" / "paper_qlearning_max").exists()
    assert (out / "provenance.json").is_file()
