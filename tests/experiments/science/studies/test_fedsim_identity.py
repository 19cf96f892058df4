"""A sync ``dfrl run`` (robot processes, the dFRL agent) and the same config replicated in one
process (fed_replicas.run_replica over fedsim.federate) give the same files bit for bit: every
robot's final table and visit counts, its table history at every share and ``metrics.csv``
(the sum of Q and the cumulative reward of every robot at every iteration, as ``repr``)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from dfrl.experiments.driver.config import ExperimentConfig, RobotSpec, resolve_config
from dfrl.experiments.driver.launcher import run
from dfrl.experiments.processes import find_swipl
from dfrl.experiments.driver.results.metrics import read_metrics
from dfrl.experiments.science.fed_replicas import (
    REPLICA_LINE,
    replica_job,
    replica_problems,
    run_replica,
)
from dfrl.experiments.science.paper_runs import recorded_wall
from dfrl.experiments.science.reproduce import PaperOptions, paper_configs
from dfrl.experiments.science.studies.fedsim import AGGREGATIONS
from dfrl.experiments.science.studies.history import history_tables

needs_swipl = pytest.mark.skipif(find_swipl() is None, reason="swipl not installed")


def paper_config(algo: str, method: str, **changes: object) -> ExperimentConfig:
    """``paper_<algo>_<method>`` (five robots in r1..r5, sync) with ``changes``."""
    return ExperimentConfig.load(resolve_config(f"paper_{algo}_{method}")).replace(**changes)


def differences(driver: Path, replica: Path) -> list[str]:
    """Every file of the two folders that differs, with the largest difference of values."""
    out = []
    a, b = history_tables(driver), history_tables(replica)
    if {r: sorted(f) for r, f in a.items()} != {r: sorted(f) for r, f in b.items()}:
        out.append(
            f"history: driver { ({r: sorted(f) for r, f in a.items()}) } "
            f"!= replica { ({r: sorted(f) for r, f in b.items()}) }"
        )
    pairs = [
        (f"history {r} it {it}", a[r][it], b[r][it]) for r in a for it in a[r] if it in b.get(r, {})
    ]
    for rid in sorted(a):
        for suffix in (".npy", ".visits.npy"):
            name = f"tables/{rid}{suffix}"
            pairs.append((name, driver / name, replica / name))
    for what, p, q in pairs:
        x, y = np.load(p), np.load(q)
        if x.shape != y.shape or x.dtype != y.dtype:
            out.append(f"{what}: {x.dtype}{x.shape} != {y.dtype}{y.shape}")
        elif not np.array_equal(x, y) or x.tobytes() != y.tobytes():
            diff = np.abs(x.astype(np.float64) - y.astype(np.float64))
            out.append(f"{what}: {int((diff > 0).sum())} entries differ, max abs {diff.max():g}")
    m_a = (driver / "metrics.csv").read_text().splitlines()
    m_b = (replica / "metrics.csv").read_text().splitlines()
    if m_a != m_b:
        first = next((i for i, (x, y) in enumerate(zip(m_a, m_b)) if x != y), None)
        where = (
            f"line {first + 1}: {m_a[first]!r} != {m_b[first]!r}"
            if first is not None
            else "one is longer"
        )
        out.append(f"metrics.csv: {len(m_a)} vs {len(m_b)} lines, first difference {where}")
    return out


def run_both(cfg: ExperimentConfig, tmp_path: Path) -> tuple[Path, Path]:
    driver, replica = tmp_path / "driver", tmp_path / "replica"
    done = run(cfg, driver, progress=None)
    assert done.ok, f"the driver run failed: {done}"
    rep = run_replica(cfg, replica)
    assert rep.shares == cfg.rounds
    return driver, replica


#: The federated runs of one seed of ``dfrl paper`` (its configs, controls included), short.
SHORT = PaperOptions(iterations=600, respite=100)


@needs_swipl
@pytest.mark.slow
@pytest.mark.parametrize("key", [k for k, _ in paper_configs(SHORT, 1)] + ["visit_average"])
def test_paper_run_and_replica_are_bit_identical(tmp_path: Path, key: str) -> None:
    """Every federated config of ``dfrl paper`` (Q-learning/SARSA x average/max, the
    off-policy reference, the shuffled-reward control), and the third built-in method on
    Q-learning: five robots in r1..r5, 600 iterations, a share every 100 (six shares), seed 2."""
    configs = dict(paper_configs(SHORT, 2))
    cfg = (
        configs[key]
        if key in configs
        else configs["qlearning/average"].replace(method=key, name=f"qlearning_{key}")
    )
    driver, replica = run_both(cfg.replace(timeout_s=600), tmp_path)
    assert sorted(history_tables(driver)["r5"]) == [100, 200, 300, 400, 500, 600]
    assert differences(driver, replica) == []


@needs_swipl
def test_small_run_and_replica_are_bit_identical(tmp_path: Path) -> None:
    """The default suite's check: two robots of the paper's, a last share off the respite
    schedule (130 = 2 x 50 + 30)."""
    cfg = paper_config("qlearning", "average", iterations=130, respite=50, timeout_s=300)
    cfg = cfg.replace(robots=cfg.robots[:2])
    driver, replica = run_both(cfg, tmp_path)
    assert sorted(history_tables(replica)["r2"]) == [50, 100, 130]
    assert differences(driver, replica) == []
    # both record the resolved config (every seed and trainer setting), the same one
    assert (driver / "config.json").read_text() == (replica / "config.json").read_text()
    summary = (replica / "summary.md").read_text()
    assert REPLICA_LINE in summary and recorded_wall(replica) >= 0


def test_replica_refuses_what_it_cannot_replicate() -> None:
    base = paper_config("qlearning", "average")
    assert replica_problems(base) == []
    assert any(p.startswith("mode") for p in replica_problems(base.replace(mode="async")))
    assert any(p.startswith("itinerary") for p in replica_problems(base.replace(itinerary="tree")))
    mixed = base.replace(
        robots=(RobotSpec("r1", "r1", "qlearning"), RobotSpec("r2", "r2", "sarsa"))
    )
    assert any("one algorithm" in p for p in replica_problems(mixed))
    with pytest.raises(ValueError, match="async"):
        run_replica(base.replace(mode="async"), Path("/nonexistent/never-written"))


def test_average_adds_in_itinerary_order_then_divides() -> None:
    """((a + b) + c) / 3, as the agent folds: the order shows when a big value cancels (adding
    b + c first would keep a: 1/3)."""
    w = [np.zeros((1, 1))] * 3
    q = [np.array([[1.0]]), np.array([[1e16]]), np.array([[-1e16]])]
    assert AGGREGATIONS["average"](q, w)[0, 0] == ((1.0 + 1e16) - 1e16) / 3.0 == 0.0
    assert (1.0 + (1e16 - 1e16)) / 3.0 != 0.0


def test_max_keeps_the_earlier_of_equal_values() -> None:
    """``(p < q) ? q : p`` (float_vectors.c): of 0.0 and -0.0 the first table's stays."""
    w = [np.zeros((1, 2))] * 2
    got = AGGREGATIONS["max"]([np.array([[-0.0, 0.0]]), np.array([[0.0, -0.0]])], w)
    assert np.signbit(got).tolist() == [[True, False]]


def test_replica_job_writes_what_the_paper_reads(tmp_path: Path) -> None:
    """The pool job's folder holds what FederatedRuns and the report read: metrics.csv (every
    robot, every iteration), the table history at every share, summary.md's wall time."""
    cfg = paper_config("sarsa", "max", iterations=45, respite=20)
    got = replica_job(cfg.to_dict(), str(tmp_path / "run"))
    out = Path(got["out"])
    assert got["shares"] == 3 and recorded_wall(out) == pytest.approx(got["wall_time_s"], abs=0.06)
    curves = read_metrics(out / "metrics.csv")
    assert sorted(curves) == ["r1", "r2", "r3", "r4", "r5"]
    assert all(c["iteration"][:45].tolist() == list(range(1, 46)) for c in curves.values())
    hist = history_tables(out)
    assert {r: sorted(f) for r, f in hist.items()} == {f"r{i}": [20, 40, 45] for i in range(1, 6)}
    final = np.load(out / "tables" / "r3.npy")
    assert np.array_equal(final, np.load(hist["r3"][45]))
    assert json.loads((out / "config.json").read_text())["method"] == "max"
    with pytest.raises(FileExistsError):
        run_replica(cfg, out)
