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
    provider = shared_provider(base, "r1", log, ProtocolLines(out, "r1"),
                               on_share=lambda: shares.append(1))
    return provider, log, out, shares


def test_a_table_without_params_stays_a_shared_table(tmp_path: Path) -> None:
    provider, *_ = _shared(StaticTable((3, 2), seed=1), tmp_path)
    assert type(provider) is SharedTable
    assert "params" not in dir(provider)          # the bridge then offers no parameters


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
    assert out.getvalue().split() == ["DFRL_EVENT", "r1", "get", "0",
                                      "DFRL_EVENT", "r1", "set", "0"]
    with open(tmp_path / "shares_r1.csv") as fh:
        (row,) = list(csv.DictReader(fh))
    assert row["digest"] == table_digest(vec)
    assert (row["round"], row["agent"], row["epoch"]) == ("2", "fed_dqn", "1")
