"""``dfrl paper`` end to end with tiny budgets: real federated runs, the control, the table
history, evaluations, band figures and a report with every test (slow: ~60 s)."""
import pytest

from dfrl.experiments.science.reproduce import PaperOptions, reproduce_paper


@pytest.mark.slow
def test_tiny_paper(tmp_path):
    opts = PaperOptions(seeds=2, iterations=400, respite=200, points=2, eval_steps=100,
                        episode_steps=50)
    rep = reproduce_paper(tmp_path, opts, progress=None)
    assert rep.ok
    assert sorted(rep.fed) == ["qlearning/average", "qlearning/max", "sarsa/average",
                               "sarsa/max"]
    assert len(rep.control_fed) == 2 and len(rep.control_sa) == 2
    hist = sorted(p.name for p in (tmp_path / "seed1" / "paper_qlearning_average" / "tables"
                                   / "history").glob("r1_*.npy"))
    assert hist == ["r1_it200.npy", "r1_it400.npy"]
    ev = (tmp_path / "seed2" / "control_qlearning_average" / "evaluations.csv").read_text()
    assert ev.startswith("robot,iteration,arena,role") and ",h2,held_out," in ev
    text = rep.report.read_text()
    for key in ("1a.", "1b.", "1c.", "1d.", "2.", "3a.", "3b.", "4.", "5.", "6."):
        assert f"### {key}" in text
    assert "Verdict:" in text and "control" in text
