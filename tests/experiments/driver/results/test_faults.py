"""Faults of a run from hand-made logs: skips, resurrections, missing rounds, the verdict."""
from __future__ import annotations

from dfrl.experiments.driver.config import ExperimentConfig, RobotSpec
from dfrl.experiments.driver.results.agent_log import (AgentLog, ControlEvent, Resurrection,
                                                RoundRecord, Skip, parse_event, _add)
from dfrl.experiments.driver.results.faults import assess


def cfg(**kw) -> ExperimentConfig:  # noqa: ANN003
    return ExperimentConfig(robots=(RobotSpec("r1", "r1"), RobotSpec("r2", "r2")),
                            iterations=400, respite=100, **kw)


def rec(n: int, skipped: tuple[Skip, ...] = ()) -> RoundRecord:
    return RoundRecord("fed", n, 1.0, 2.0, 2, 10, "average", ("r1",), skipped)


def test_missing_rounds_lost_robots_and_the_verdict() -> None:
    log = AgentLog("fed", [rec(1), rec(2, (Skip("r2", "connection refused"),)), rec(4)])
    log.resurrections.append(Resurrection(3, 1, "10.0.0.1:7001", "10.0.0.2:7001"))
    f = assess(cfg(), [(log, 4)], {"r2": "unreachable for 12 s"}, ["r2 unreachable ..."])
    assert f.missing_rounds == {"fed": [3]}
    assert f.skips == ["fed round 2: r2 skipped (connection refused)"]
    assert "epoch 1" in f.resurrections[0] and "10.0.0.2:7001" in f.resurrections[0]
    assert not f.complete(cfg())
    assert not f.complete(cfg(tolerate_missing_rounds=1))
    assert f.complete(cfg(tolerate_missing_rounds=1, tolerate_lost_robots=1))
    text = "\n".join(f.lines())
    for word in ("MISSING rounds of fed (1): 3", "LOST robot r2", "skipped stops (1)",
                 "resurrections (1)", "stalls (1)"):
        assert word in text


def test_a_stop_command_shortens_the_plan_and_a_clean_run_is_complete() -> None:
    log = AgentLog("fed", [rec(1), rec(2)], controls=[ControlEvent(2, "stop", "applied")])
    f = assess(cfg(), [(log, 4)], {})
    assert f.missing_rounds == {"fed": []} and f.complete(cfg()) and f.lines() == []


def test_the_resurrected_event_is_read() -> None:
    log = AgentLog("fed")
    assert _add(log, parse_event('{"event":"resurrected","agent":"fed","round":5,"epoch":2,'
                                 '"from":"h1:7001","dead":"h2:7001"}'))
    assert log.resurrections == [Resurrection(5, 2, "h1:7001", "h2:7001")]


def test_a_robot_skipped_then_visited_again_is_no_complete_federation() -> None:
    # r2 missed rounds 2 and 3 and was visited again in round 4: not lost at the end, but it
    # took no part in two rounds, so the federation is not complete (the control: the same
    # log without the skips is)
    both = ("r1", "r2")
    gone = (Skip("r2", "no answer within 3 s"),)
    rounds = [RoundRecord("fed", 1, 1.0, 2.0, 2, 10, "average", both),
              RoundRecord("fed", 2, 1.0, 2.0, 2, 10, "average", ("r1",), gone),
              RoundRecord("fed", 3, 1.0, 2.0, 2, 10, "average", ("r1",), gone),
              RoundRecord("fed", 4, 1.0, 2.0, 2, 10, "average", both)]
    f = assess(cfg(), [(AgentLog("fed", rounds), 4)], {})
    assert f.missed == {"r2": "missed 2 round(s) of fed: 2, 3 (lost at round 2, rejoined at "
                              "round 4)"}
    assert not f.complete(cfg()) and f.complete(cfg(tolerate_lost_robots=1))
    assert "- MISSED rounds: r2 missed 2 round(s)" in "\n".join(f.lines())
    clean = [RoundRecord("fed", n, 1.0, 2.0, 2, 10, "average", both) for n in range(1, 5)]
    assert assess(cfg(), [(AgentLog("fed", clean), 4)], {}).complete(cfg())


def test_skips_of_a_robot_after_it_finished_are_no_missed_rounds() -> None:
    # r2 (a joiner with fewer iterations) ended after round 2; the agent skipped it in rounds
    # 3 and 4: nothing missed when it had finished, missed rounds when it had not (control)
    both = ("r1", "r2")
    gone = (Skip("r2", "connection refused"),)
    rounds = [RoundRecord("fed", 1, 1.0, 2.0, 2, 10, "average", both),
              RoundRecord("fed", 2, 1.0, 2.0, 2, 10, "average", both),
              RoundRecord("fed", 3, 1.0, 2.0, 2, 10, "average", ("r1",), gone),
              RoundRecord("fed", 4, 1.0, 2.0, 2, 10, "average", ("r1",), gone)]
    ended = assess(cfg(), [(AgentLog("fed", rounds), 4)], {}, finished=["r2"])
    assert ended.missed == {} and ended.complete(cfg())
    cut = assess(cfg(), [(AgentLog("fed", rounds), 4)], {})
    assert cut.missed["r2"].startswith("missed 2 round(s) of fed: 3, 4 (lost at round 3, "
                                       "never visited again)") and not cut.complete(cfg())
