"""Reference tables: the distance and the combination on hand-computed tables, the cache's
checksums, and one end-to-end build with a tiny budget (about 10 s)."""

from __future__ import annotations

import hashlib
import json
import math

import numpy as np
import pytest

from dfrl.experiments.science.reference import (
    REFERENCE_FORMAT,
    SHIPPED,
    Reference,
    ReferenceError,
    combine,
    default_cache,
    recipe_key,
    reference_name,
    reference_recipe,
    table_error,
)
from dfrl.experiments.science.reference_store import load_reference, reference_table, save_reference


# -- the distance ------------------------------------------------------------------------------
def test_table_error_by_hand() -> None:
    # Prepare: 3 states x 2 actions; the reference visited state 2's second action too rarely
    ref = np.array([[1.0, 3.0], [2.0, 0.0], [4.0, 5.0]])
    visits = np.array([[10, 12], [30, 10], [50, 9]])
    table = np.array([[2.0, 1.0], [2.0, 2.0], [100.0, -100.0]])
    # Execute
    e = table_error(table, ref, visits, min_visits=10)
    # Assert: pairs (0,0) (0,1) (1,0) (1,1) (2,0); differences 1, -2, 0, 2, 96
    # rms = sqrt((1 + 4 + 0 + 4 + 9216) / 5) = sqrt(1845) = 42.9535
    assert e.pairs == 5
    assert e.rms == pytest.approx(math.sqrt(1845.0))
    # reference RMS over them: sqrt((1 + 9 + 4 + 0 + 16) / 5) = sqrt(6); relative = sqrt(307.5)
    assert e.relative == pytest.approx(math.sqrt(1845.0 / 6.0))
    # states with both actions counted: 0 and 1. State 0: table picks 0, reference 1: 1.
    # State 1: table ties {0, 1}, reference picks 0: half the tie-breaks miss: 0.5. Mean 0.75
    assert e.states == 2
    assert e.disagreement == pytest.approx(0.75)


def test_table_error_zero_table_and_defaults() -> None:
    ref = np.array([[1.0, -1.0, 2.0], [0.5, 0.5, 0.0]])
    e = table_error(np.zeros_like(ref), ref)  # no visits: every pair counts
    assert (e.pairs, e.states) == (6, 2)
    assert e.relative == pytest.approx(1.0)  # the zero table is at exactly 1
    # state 0: reference best {2}, zero table ties all 3: 2/3 miss; state 1: best {0, 1}: 1/3
    assert e.disagreement == pytest.approx(0.5)
    assert table_error(ref, ref).rms == 0.0 and table_error(ref, ref).disagreement == 0.0


def test_table_error_takes_visits_from_a_reference_and_counts_nothing_as_nan() -> None:
    q = np.array([[1.0, 2.0]])
    ref = Reference(q=q, visits=np.array([[3, 0]]), runs=np.array([[1, 0]]), recipe={}, built={})
    e = table_error(np.array([[0.0, 0.0]]), ref, min_visits=1)
    assert (e.pairs, e.states, e.rms) == (1, 0, 1.0)
    assert math.isnan(e.disagreement)
    none = table_error(q, ref, min_visits=5)
    assert none.pairs == 0 and math.isnan(none.rms) and math.isnan(none.relative)


def test_table_error_refuses_bad_input() -> None:
    ref = np.zeros((2, 3))
    with pytest.raises(ValueError, match="shape"):
        table_error(np.zeros((3, 3)), ref)
    with pytest.raises(ValueError, match="finite"):
        table_error(np.full((2, 3), np.nan), ref)
    with pytest.raises(ValueError, match="visits"):
        table_error(ref, ref, visits=-np.ones((2, 3)))


def test_combine_means_over_the_runs_that_updated_a_pair() -> None:
    t1 = np.array([[2.0, 0.0], [1.0, 7.0]])
    t2 = np.array([[4.0, 5.0], [0.0, 9.0]])
    v1 = np.array([[1, 0], [2, 0]])
    v2 = np.array([[3, 4], [0, 0]])
    q, visits, runs = combine([t1, t2], [v1, v2], initial_q=-1.0)
    # (0,0): both runs: 3; (0,1): run 2 alone: 5; (1,0): run 1 alone: 1; (1,1): none: -1
    assert q.tolist() == [[3.0, 5.0], [1.0, -1.0]]
    assert visits.tolist() == [[4, 4], [2, 0]]
    assert runs.tolist() == [[2, 1], [1, 0]]


# -- recipes and the cache ---------------------------------------------------------------------
def test_recipe_name_and_key() -> None:
    a = reference_recipe("r1", "qlearning", 3000, [1, 2])
    assert a["seeds"] == [1, 2] and a["config"]["seed"] == 0
    assert a["config"]["iterations"] == 3000
    name = reference_name(a)
    assert name.startswith("r1-qlearning-3000x2-") and name.endswith(recipe_key(a)[:12])
    assert reference_name(reference_recipe("r1", "qlearning", 3000, [1, 3])) != name
    assert reference_name(reference_recipe("arenas/my arena.json", "sarsa", 10, [1])).startswith(
        "my_arena-sarsa-10x1-"
    )
    for bad in ({"seeds": []}, {"seeds": [1, 1]}, {"iterations": 0}, {"algo": "dqn"}):
        kw = {"arena": "r1", "algo": "qlearning", "iterations": 10, "seeds": [1], **bad}
        with pytest.raises(ValueError):
            reference_recipe(**kw)


def test_default_cache_follows_the_environment(monkeypatch: pytest.MonkeyPatch, tmp_path) -> None:
    monkeypatch.setenv("DFRL_REFERENCE_CACHE", str(tmp_path / "refs"))
    assert default_cache() == tmp_path / "refs"
    monkeypatch.delenv("DFRL_REFERENCE_CACHE")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert default_cache() == tmp_path / "xdg" / "dfrl" / "references"
    assert not (tmp_path / "xdg").exists()  # a getter creates nothing


def _fake(tmp_path) -> tuple[Reference, object]:
    recipe = reference_recipe("r1", "qlearning", 10, [1, 2])
    ref = Reference(
        q=np.arange(6.0).reshape(3, 2),
        visits=np.array([[1, 2], [3, 4], [5, 6]]),
        runs=np.ones((3, 2), dtype=np.int64),
        recipe=recipe,
        built={"seconds": 0},
    )
    return ref, save_reference(ref, tmp_path)


def test_saved_reference_loads_back_with_its_checksums(tmp_path) -> None:
    ref, side = _fake(tmp_path)
    meta = json.loads(side.read_text())
    assert meta["format"] == REFERENCE_FORMAT and meta["recipe"] == ref.recipe
    qf = tmp_path / f"{ref.name}.q.npy"
    assert meta["sha256"][qf.name] == hashlib.sha256(qf.read_bytes()).hexdigest()
    back = load_reference(side)
    assert np.array_equal(back.q, ref.q) and np.array_equal(back.visits, ref.visits)
    assert back.recipe == ref.recipe and back.path == side


def test_corrupted_or_missing_files_are_errors_naming_the_file(tmp_path) -> None:
    ref, side = _fake(tmp_path)
    qf = tmp_path / f"{ref.name}.q.npy"
    good = qf.read_bytes()
    data = bytearray(good)
    data[-1] ^= 0x01  # one bit of the last value
    qf.write_bytes(bytes(data))
    with pytest.raises(ReferenceError, match=f"{qf.name}: sha256"):
        load_reference(side)
    with pytest.raises(ReferenceError, match=f"{qf.name}: sha256"):  # never rebuilt silently
        reference_table("r1", "qlearning", 10, [1, 2], cache=tmp_path)
    qf.write_bytes(good)
    assert load_reference(side).q.tolist() == ref.q.tolist()
    (tmp_path / f"{ref.name}.visits.npy").unlink()
    with pytest.raises(ReferenceError, match="visits.npy: missing"):
        load_reference(side)
    side.write_text("{}")
    with pytest.raises(ReferenceError, match="not a dfrl-reference/1"):
        load_reference(side)


# -- end to end --------------------------------------------------------------------------------
def test_reference_end_to_end(tmp_path) -> None:
    """A tiny reference (R1, Q-learning, 3,000 iterations x seeds 1 and 2), built, cached,
    reproduced bit for bit, and the error falling with training for a seed it was not built
    from; the control (the zero table) must be further than either run, and could fail.
    Against so crude a reference the fall from 1,000 to 3,000 iterations is no law: it held
    for seeds 3, 4, 5, 6 and 8 and not for 7 (measured once); seed 3 is deterministic, so
    this test checks the pipeline, not the statistic (README: the curve against the shipped
    reference)."""
    from dfrl.robots.training import TrainerConfig, train

    # Prepare / Execute
    ref = reference_table("r1", "qlearning", 3000, [1, 2], cache=tmp_path / "a")
    again = reference_table("r1", "qlearning", 3000, [1, 2], cache=tmp_path / "a")
    twin = reference_table("r1", "qlearning", 3000, [1, 2], cache=tmp_path / "b")
    short = train(TrainerConfig(arena="r1", algo="qlearning", seed=3, iterations=1000))
    long = train(TrainerConfig(arena="r1", algo="qlearning", seed=3, iterations=3000))
    # Assert: the cache
    assert ref.path is not None and ref.path.parent == tmp_path / "a"
    assert again.built == ref.built  # loaded, not rebuilt
    assert np.array_equal(twin.q, ref.q)  # the same recipe, the same bits
    sums = json.loads(ref.path.read_text())["sha256"]
    assert sums == json.loads(twin.path.read_text())["sha256"]
    assert ref.built["seed_rms"] > 0 and len(ref.built["seed_rms_per_run"]) == 2
    assert (ref.visits >= 10).sum() > 20  # R1 visits a few dozen pairs
    # Assert: the error falls with training; the zero table is further than both
    assert ref.q.shape == short.q_table.shape == (81, 3)
    e_short, e_long = table_error(short.q_table, ref), table_error(long.q_table, ref)
    e_zero = table_error(np.zeros_like(ref.q), ref)
    assert e_zero.relative == pytest.approx(1.0)
    assert e_zero.rms > e_short.rms > e_long.rms
    # Assert: a corrupted cache is an error naming the file
    qf = tmp_path / "a" / f"{ref.name}.q.npy"
    qf.write_bytes(qf.read_bytes()[:-8] + np.float64(1e9).tobytes())
    with pytest.raises(ReferenceError, match=str(qf)):
        reference_table("r1", "qlearning", 3000, [1, 2], cache=tmp_path / "a")


# -- the shipped reference ---------------------------------------------------------------------
SHIPPED_RECIPE = ("r1", "qlearning", 50_000, [1, 2, 3, 4, 5])


def test_shipped_reference_verifies_and_matches_todays_defaults(tmp_path) -> None:
    """The shipped R1 reference loads with its checksums and is what ``reference_table``
    returns for its recipe without building (an empty cache); if the default configuration
    changes, its name no longer matches and this test says so."""
    ref = reference_table(*SHIPPED_RECIPE, cache=tmp_path)
    assert ref.path is not None and ref.path.parent == SHIPPED
    assert not any(tmp_path.iterdir())  # nothing built
    assert ref.recipe == reference_recipe(*SHIPPED_RECIPE)
    assert ref.q.shape == (81, 3)
    # the counts the README quotes: 140 pairs updated, 116 at least 10 times, 80 by all 5 runs
    assert ((ref.visits > 0).sum(), (ref.visits >= 10).sum(), (ref.runs == 5).sum()) == (
        140,
        116,
        80,
    )
    assert table_error(ref.q, ref).states == 34
    # a 50,000-iteration run is at about half the zero table's distance: the floor of a run
    zero = table_error(np.zeros_like(ref.q), ref)
    assert 0.3 < ref.built["seed_rms"] / zero.rms < 0.8


@pytest.mark.slow
def test_shipped_reference_rebuilds_bit_for_bit(tmp_path) -> None:
    """About 110 s with two processes: the shipped arrays are what today's code trains."""
    shipped = reference_table(*SHIPPED_RECIPE, cache=tmp_path)
    again = reference_table(*SHIPPED_RECIPE, cache=tmp_path, rebuild=True, jobs=2)
    assert again.path is not None and again.path.parent == tmp_path
    assert np.array_equal(again.q, shipped.q) and np.array_equal(again.visits, shipped.visits)
    assert (
        json.loads(again.path.read_text())["sha256"]
        == json.loads(shipped.path.read_text())["sha256"]
    )
