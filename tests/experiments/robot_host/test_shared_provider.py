"""What a robot process offers the bridge (robot_host/table.py): a table, or a table and its
parameters, or parameters only; a parameter write is a share like a table write."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from dfrl.experiments.robot_host.files import SHARE_FIELDS, CsvLog, table_digest
from dfrl.experiments.robot_host.lines import ProtocolLines
from dfrl.experiments.robot_host.table import SharedLearner, SharedTable, shared_provider
from dfrl.pybridge.providers import StaticParams, StaticTable

LAYOUT = [("w", (3, 2)), ("b", (2,))]


def _shared(base, tmp_path: Path):
    out = io.StringIO()
    log = CsvLog(tmp_path / "shares_r1.csv", SHARE_FIELDS)
    shares: list[int] = []
    provider = shared_provider(
        base, "r1", log, ProtocolLines(out, "r1"), on_share=lambda: shares.append(1)
    )
    return provider, log, out, shares


def test_a_table_without_params_stays_a_shared_table(tmp_path: Path) -> None:
    provider, *_ = _shared(StaticTable((3, 2), seed=1), tmp_path)
    assert type(provider) is SharedTable
    assert "params" not in dir(provider)  # the bridge then offers no parameters


def test_a_params_write_is_a_share(tmp_path: Path) -> None:
    base = StaticParams(LAYOUT, seed=1, samples=9)
    provider, log, out, shares = _shared(base, tmp_path)
    assert isinstance(provider, SharedLearner)
    assert provider.learner_kind == "function" and provider.samples == 9
    assert provider.param_layout == LAYOUT
    assert np.array_equal(provider.params, base.params)
    provider.params_read()
    vec = np.arange(8.0)
    provider.set_params_from(vec, {"round": 2, "agent": "fed_dqn", "epoch": 1})
    log.flush()
    assert base.sets == 1 and np.array_equal(base.params, vec)
    assert provider.shares == 1 and shares == [1]
    assert out.getvalue().split() == [
        "DFRL_EVENT",
        "r1",
        "get",
        "0",
        "DFRL_EVENT",
        "r1",
        "set",
        "0",
    ]
    with open(tmp_path / "shares_r1.csv") as fh:
        (row,) = list(csv.DictReader(fh))
    assert row["digest"] == table_digest(vec)
    assert (row["round"], row["agent"], row["epoch"]) == ("2", "fed_dqn", "1")
    assert float(row["q_sum"]) == 28.0  # the sum the write left: 0 + 1 + ... + 7


def test_a_table_write_records_the_sum_it_left(tmp_path: Path) -> None:
    # Prepare: a static 3x2 table
    provider, log, _, _ = _shared(StaticTable((3, 2), seed=1), tmp_path)
    table = np.array([[0.5, 1.0], [2.0, -1.0], [0.25, 0.0]])
    # Execute: one write
    provider.set_q_table_from(table, {"round": 1, "agent": "fed_qlearning", "epoch": 1})
    log.flush()
    # Assert: the row holds the table's sum (what metrics.csv's q_sum shows after a share)
    with open(tmp_path / "shares_r1.csv") as fh:
        (row,) = list(csv.DictReader(fh))
    assert float(row["q_sum"]) == 2.75 and provider.q_sum == 2.75
