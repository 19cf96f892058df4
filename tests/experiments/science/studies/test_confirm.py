"""``--confirm-seeds K``: ``dfrl speedup`` and ``transfer-study`` on the batched simulator run
their headline contrasts again on pybullet with their first K seeds; the confirmation holds
the study's own batched numbers and those of the same study run on pybullet alone, its
section and JSON appear only when asked for, and the agreement rule is the documented one."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import pytest

from dfrl.experiments.cli import main
from dfrl.experiments.science.studies.confirm import Confirmation, Estimate, markdown

#: On pybullet, one robot of seed 3 reaches 0.96 at 100 iterations, of seeds 1 and 2 at 200.
SPEEDUP = [
    "speedup",
    "--robots",
    "1",
    "2",
    "--n-seeds",
    "3",
    "--iterations",
    "600",
    "--budget",
    "1=600",
    "--share-every",
    "100",
    "--grid",
    "100",
    "--score-every",
    "200",
    "--eval-steps",
    "50",
    "--targets",
    "0.999",
    "0.96",
    "--resamples",
    "200",
    "--jobs",
    "1",
]
TRANSFER = [
    "transfer-study",
    "--targets",
    "h1",
    "--iterations",
    "40",
    "--respite",
    "20",
    "--learn",
    "40",
    "--eval-every",
    "20",
    "--eval-steps",
    "20",
    "--resamples",
    "200",
    "--jobs",
    "1",
    "--threshold-iterations",
    "40",
    "--threshold-runs",
    "2",
]


def _no_wall(text: str) -> str:
    return re.sub(r"Wall time \d+ s", "Wall time - s", text)


def test_speedup_confirms_its_headline_with_pybullets_own_numbers(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "confirmed"
    assert main([*SPEEDUP, "--confirm-seeds", "2", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    data = json.loads((out / "speedup.json").read_text())
    found = data["confirmation"]
    assert [c["contrast"] for c in found] == [
        "homogeneous T(1)/T(2), error<=0.999",
        "homogeneous T(1)/T(2), error<=0.96",
        "homogeneous T(1)/T(2), score>=0.7",
    ]
    # the batched side is the study's row; the pybullet side the same analysis of a pybullet
    # study of seeds 1 and 2 (N = 1 and 2, homogeneous), run on its own here
    rows = {
        r["measure"]: r
        for r in data["rows"]
        if r["condition"] == "homogeneous" and r["robots"] == 2
    }
    pyb = tmp_path / "pybullet"
    assert (
        main(
            [
                *SPEEDUP,
                "--n-seeds",
                "2",
                "--conditions",
                "homogeneous",
                "--sim",
                "pybullet",
                "--out",
                str(pyb),
            ]
        )
        == 0
    )
    alone = {
        r["measure"]: r
        for r in json.loads((pyb / "speedup.json").read_text())["rows"]
        if r["robots"] == 2
    }
    for c in found:
        m = c["contrast"].rsplit(", ", 1)[1]
        assert c["batched"]["n"] == 3 and c["pybullet"]["n"] == 2
        assert {k: c["batched"][k] for k in ("estimate", "low", "high")} == {
            k: rows[m]["ratio"][k] for k in ("estimate", "low", "high")
        }
        assert {k: c["pybullet"][k] for k in ("estimate", "low", "high")} == {
            k: alone[m]["ratio"][k] for k in ("estimate", "low", "high")
        }
        assert c["pybullet"]["outcomes"] == {"linear": "cannot judge", "any": "cannot judge"}
        assert c["agrees"] == (c["contains"] or c["same_verdict"])
    # error <= 0.999 is reached at the first grid point on both: ratio 1, contained
    assert found[0]["pybullet"]["estimate"] == 1.0 and found[0]["agrees"]
    md = (out / "speedup.md").read_text()
    assert "### Confirmation in pybullet" in md and "### Confirmation in pybullet" in printed
    assert (
        "| homogeneous T(1)/T(2), error<=0.999 | 1 [1, 1] (n = 3) | linear refuted; "
        "any refuted | 1 [1, 1] (n = 2) | linear cannot judge; any cannot judge | yes |" in md
    )


def test_speedup_without_confirmation_is_unchanged(tmp_path: Path) -> None:
    docs = []
    for extra in ([], ["--confirm-seeds", "0"]):
        out = tmp_path / f"k{len(extra)}"
        assert main([*SPEEDUP, *extra, "--out", str(out)]) == 0
        data = json.loads((out / "speedup.json").read_text())
        data.pop("wall_s")
        for run in data["runs"]:  # each federation's own wall time
            run.pop("seconds")
        docs.append((data, _no_wall((out / "speedup.md").read_text())))
    assert docs[0] == docs[1]
    assert "confirmation" not in docs[0][0] and "pybullet" not in docs[0][1]


@pytest.mark.parametrize(
    "args, said",
    [
        (["--confirm-seeds", "4"], "--confirm-seeds 4: the study has only 3 seeds"),
        (["--confirm-seeds", "1", "--sim", "pybullet"], "this one runs on pybullet"),
        (["--confirm-seeds", "-1"], "--confirm-seeds must be >= 0"),
    ],
)
def test_a_confirmation_that_cannot_be_run_is_refused(
    args: list[str], said: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main([*SPEEDUP, *args]) == 2
    assert said in capsys.readouterr().err
    assert main([*TRANSFER, "--seeds", "1", "2", "3", *args]) == 2
    assert said in capsys.readouterr().err


def test_transfer_confirms_its_primary_claims(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "confirmed"
    assert (
        main([*TRANSFER, "--seeds", "1", "2", "3", "--confirm-seeds", "2", "--out", str(out)]) == 0
    )
    printed = capsys.readouterr().out
    doc = json.loads((out / "transfer_study.json").read_text())
    found = doc["confirmation"]
    controls = [
        "standalone_r1",
        "standalone_r2",
        "standalone_r3",
        "standalone_r4",
        "standalone_r5",
        "zeros",
    ]
    assert [c["contrast"] for c in found] == [
        f"{m}: federated_average - {c}"
        for m in ("collisions_per_1000", "score_auc")
        for c in controls
    ]
    claims = {(c["measure"], c["control"]): c for c in doc["claims"]}
    # the pybullet side: the same study on pybullet alone, seeds 1 and 2, the batched
    # study's threshold given
    base = doc["rows"][0]["threshold_base"]
    pyb = tmp_path / "pybullet"
    assert (
        main(
            [
                *TRANSFER,
                "--seeds",
                "1",
                "2",
                "--sim",
                "pybullet",
                "--threshold",
                f"h1={base!r}",
                "--out",
                str(pyb),
            ]
        )
        == 0
    )
    alone = {
        (c["measure"], c["control"]): c
        for c in json.loads((pyb / "transfer_study.json").read_text())["claims"]
    }
    for c in found:
        key = tuple(c["contrast"].replace(": federated_average - ", " ").split(" "))
        assert (
            c["batched"]["estimate"],
            c["batched"]["low"],
            c["batched"]["high"],
            c["batched"]["n"],
        ) == tuple(claims[key][k] for k in ("estimate", "low", "high", "n"))
        assert (
            c["pybullet"]["estimate"],
            c["pybullet"]["low"],
            c["pybullet"]["high"],
            c["pybullet"]["n"],
        ) == tuple(alone[key][k] for k in ("estimate", "low", "high", "n"))
        assert c["batched"]["n"] == 3 and c["pybullet"]["n"] == 2
    assert "## Confirmation in pybullet" in printed
    assert "## Confirmation in pybullet" in (out / "transfer_study.md").read_text()
    # without --confirm-seeds: no section, no key
    plain = tmp_path / "plain"
    assert (
        main([*TRANSFER, "--seeds", "1", "2", "3", "--confirm-seeds", "0", "--out", str(plain)])
        == 0
    )
    again = json.loads((plain / "transfer_study.json").read_text())
    assert "confirmation" not in again and again["claims"] == doc["claims"]
    assert "Confirmation in pybullet" not in (plain / "transfer_study.md").read_text()


def _estimate(value: float, low: float, high: float, outcome: str) -> Estimate:
    return Estimate(value, low, high, 5, outcome, (outcome,))


def test_agreement_is_containment_or_the_same_verdict() -> None:
    inside = Confirmation(
        "a", _estimate(2.0, 1.5, 2.5, "holds"), _estimate(1.0, 0.5, 2.0, "not significant")
    )
    same = Confirmation("b", _estimate(2.0, 1.5, 2.5, "holds"), _estimate(3.0, 2.5, 3.5, "holds"))
    neither = Confirmation(
        "c", _estimate(2.0, 1.5, 2.5, "holds"), _estimate(3.0, 2.1, 3.5, "not significant")
    )
    unknown = Confirmation(
        "d",
        _estimate(math.nan, 0.0, math.inf, "not significant"),
        _estimate(1.0, 0.0, math.inf, "cannot judge"),
    )
    both = Confirmation(
        "e",
        _estimate(math.nan, 0.0, math.inf, "not significant"),
        _estimate(math.nan, 0.0, math.inf, "cannot judge"),
    )
    assert (inside.contains, inside.same_verdict, inside.agrees) == (True, False, True)
    assert (same.contains, same.same_verdict, same.agrees) == (False, True, True)
    assert (neither.contains, neither.agrees) == (False, False)
    assert (unknown.contains, unknown.agrees) == (False, False)
    assert both.agrees
    text = markdown([inside, same, neither, unknown, both], "Design.", 3.0)
    assert "**2 of 5 contrasts disagree**: c; d." in text
    assert (
        "| c | 2 [1.5, 2.5] (n = 5) | holds | 3 [2.1, 3.5] (n = 5) | not significant "
        "| **no** |" in text
    )
    assert "1 of 1 contrasts agree." in markdown([inside], "Design.", 3.0)
