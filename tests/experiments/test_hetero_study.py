"""``dfrl hetero`` on a tiny budget on pybullet: the runs, the rows, the paired comparisons and
the files; a run is the same with the same seed, and federating changes the robots (the
control: the same robots alone end elsewhere)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from dfrl.experiments.cli import main
from dfrl.experiments.science.studies.hetero import HeteroOptions, run, run_one

TINY = HeteroOptions(
    seeds=(1, 2),
    iterations=60,
    respite=30,
    eval_at=(30, 60),
    eval_steps=20,
    episode_steps=20,
    jobs=1,
    sim="pybullet",
)


def test_study_on_a_tiny_budget(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    res = run(TINY, tmp_path / "out")
    # 2 seeds x (1 + 1 + 2 + 2 robots) x 2 evaluations
    assert len(res.rows) == 2 * 6 * 2
    assert {(c["role"], c["run"], c["baseline"]) for c in res.comparisons} == {
        ("dqn", "mixed", "dqn_alone"),
        ("ql", "mixed", "ql_alone"),
        ("ql", "ql_pair", "ql_alone"),
    }
    for c in res.comparisons:
        assert c["score"]["n"] == 2
        assert c["score"]["mean"] == pytest.approx(
            c[f"score_{c['run']}"] - c[f"score_{c['baseline']}"]
        )
    assert res.residuals["shares"] == 2 * 2 and res.residuals["max"] <= 0.05
    # the same seed gives the same run (rows and final parameters)...
    again = run_one("mixed", 1, TINY)
    order = lambda r: (r["role"], r["iteration"])  # noqa: E731
    assert sorted(again["rows"], key=order) == [
        r for r in res.rows if r["seed"] == 1 and r["run"] == "mixed"
    ]
    assert again["digests"] == res.digests["mixed/1"]
    # ...and federating changes both robots: alone, the same robots end elsewhere
    assert res.digests["mixed/1"]["dqn"] != res.digests["dqn_alone/1"]["dqn"]
    assert res.digests["mixed/1"]["ql"] != res.digests["ql_alone/1"]["ql"]
    assert res.digests["ql_pair/1"]["ql"] != res.digests["ql_alone/1"]["ql"]
    saved = json.loads((tmp_path / "out" / "results.json").read_text())
    assert saved["comparisons"] == json.loads(json.dumps(res.comparisons))
    assert json.loads((tmp_path / "out" / "options.json").read_text())["iterations"] == 60
    assert len((tmp_path / "out" / "rows.csv").read_text().splitlines()) == 1 + len(res.rows)
    # bad options are refused with the option named, exit 2
    assert main(["hetero", "--seed", "1"]) == 2
    assert "seeds: at least two distinct seeds" in capsys.readouterr().err
    assert main(["hetero", "--seeds", "1", "2", "--eval-at", "9000"]) == 2
    assert "eval_at" in capsys.readouterr().err
