""" "Did you mean" for keys and values: the edit distance on hand-computed pairs, every single
slip (a letter dropped, added, changed, two swapped) of every name a config checks caught,
and the messages of a real ``dfrl run`` that refuses a misspelt config."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from dfrl.experiments.config_rules import trainer_choices
from dfrl.experiments.driver.config_check import (
    BUILTIN_METHODS,
    EXPERIMENT_RULES,
    FEDERATIONS,
    ITINERARIES,
    ROBOT_RULES,
    check_experiment,
)
from dfrl.experiments.robot_host.config import modes
from dfrl.experiments.suggestions import did_you_mean, edit_distance, near_names
from dfrl.experiments.config_rules import known_algorithms


@pytest.mark.parametrize(
    "a, b, d",
    [
        ("", "", 0),
        ("abc", "", 3),
        ("iteratons", "iterations", 1),  # a letter dropped
        ("qlearing", "qlearning", 1),
        ("sasra", "sarsa", 1),  # dropped; swapped
        ("averagee", "average", 1),
        ("avarage", "average", 1),  # added; changed
        ("ca", "abc", 3),  # the restricted form: no edit of a swapped pair
        ("kitten", "sitting", 3),
        ("flaw", "lawn", 2),
    ],
)
def test_edit_distance_hand_computed(a: str, b: str, d: int) -> None:
    assert edit_distance(a, b) == d
    assert edit_distance(b, a) == d


#: What a slip adds or changes a letter to: a vowel most names have, consonants few have, a
#: digit and _ (every letter would be 37 times the work for the same cases).
SLIP_LETTERS = "aeqz1_"


def slips(word: str) -> set[str]:
    """Every word one slip away from ``word`` (letters added or changed: SLIP_LETTERS)."""
    letters = SLIP_LETTERS
    out = {word[:i] + word[i + 1 :] for i in range(len(word))}
    out |= {word[:i] + c + word[i:] for i in range(len(word) + 1) for c in letters}
    out |= {word[:i] + c + word[i + 1 :] for i in range(len(word)) for c in letters}
    out |= {word[:i] + word[i + 1] + word[i] + word[i + 2 :] for i in range(len(word) - 1)}
    return out - {word}


NAME_LISTS = {
    "experiment keys": sorted(EXPERIMENT_RULES),
    "robot keys": sorted(ROBOT_RULES),
    "algorithms": known_algorithms(),
    "methods": list(BUILTIN_METHODS),
    "itineraries": list(ITINERARIES),
    "federations": list(FEDERATIONS),
    "modes": list(modes()),
    **{f"trainer.{k}": v for k, v in trainer_choices().items()},
}


@pytest.mark.parametrize("what", sorted(NAME_LISTS))
def test_every_slip_of_every_name_is_caught(what: str) -> None:
    names = NAME_LISTS[what]
    missed = []
    for name in names:
        for typo in slips(name):
            if typo in names:
                continue  # a slip that makes another name is no typo
            near = near_names(typo, names)
            if name not in near and sum(edit_distance(typo, n) == 1 for n in names) <= 3:
                missed.append((typo, name, near))  # not one of more than 3 equally near
    assert not missed, missed[:10]


def test_unrelated_and_ambiguous_words_get_no_suggestion() -> None:
    assert near_names("ppo", known_algorithms()) == []
    assert near_names("r9", ["h1", "h2", "r1", "r2", "r3", "r4", "r5"]) == []  # 5 equally near
    assert near_names("colour", sorted(EXPERIMENT_RULES)) == []
    assert did_you_mean(3, ["a"]) == ""
    assert did_you_mean("algorithm", sorted(ROBOT_RULES)) == "did you mean 'algo'?"  # a prefix


def test_the_config_check_names_the_nearest_key_and_value() -> None:
    problems = check_experiment(
        {
            "name": "x",
            "iteratons": 5,
            "method": "averge",
            "itinerary": "tre",
            "robots": [{"id": "r1", "arena": "r11", "algo": "qlearing"}],
            "methods": {"sars": "max"},
            "trainer": {"collision_response": "respwn"},
        }
    )
    for line in [
        "iteratons: unknown key; did you mean 'iterations'?",
        "robots[0].algo: unknown algorithm 'qlearing' (did you mean 'qlearning'?); "
        "known: dqn, linear, qlearning, sarsa",
        "method: unknown method 'averge' (did you mean 'average'?)",
        "itinerary: unknown itinerary 'tre' (did you mean 'tree'?)",
        "methods.sars: unknown algorithm 'sars' (did you mean 'sarsa'?)",
        "nor an existing file (did you mean 'r1'?)",
        "trainer.collision_response: unknown value 'respwn' (did you mean 'respawn'?); "
        "known: respawn, continue",
    ]:
        assert any(line in p for p in problems), (line, problems)


def test_dfrl_run_says_what_was_meant(tmp_path: Path) -> None:
    # Prepare: the new user's config (a letter dropped in a key and in a value)
    cfg = {
        "name": "typo",
        "iteratons": 200,
        "respite": 50,
        "robots": [
            {"id": "r1", "arena": "r1", "algo": "qlearing"},
            {"id": "r2", "arena": "r2", "algo": "qlearning"},
        ],
    }
    path = tmp_path / "typo.json"
    path.write_text(json.dumps(cfg))
    # Execute: the real command line
    out = subprocess.run(
        [sys.executable, "-m", "dfrl", "run", str(path), "--out", str(tmp_path / "out")],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    # Assert: refused before anything started, each slip named with its correction
    assert out.returncode == 2, out.stderr
    assert "iteratons: unknown key; did you mean 'iterations'?" in out.stderr
    assert "robots[0].algo: unknown algorithm 'qlearing' (did you mean 'qlearning'?)" in out.stderr
    assert not (tmp_path / "out").exists()
