"""The questions ``dfrl paper`` answers, each with one primary measure, one contrast per row
and a smallest effect of interest delta stated up front.

=== ======================================== ====================================== =========
key question                                 a row: A - B, paired by seed           measure
=== ======================================== ====================================== =========
L   do robots learn?                         trained - ``untrained`` (the zero       own score
                                             table) and trained - its learning
                                             control ``control/<trained>``, per
                                             algorithm, standalone and federated
F   does federation help in the robots'      ``<algo>/<method>`` -                  own score
    own arenas?                              ``standalone/<algo>``
T   do federated tables transfer better?     ``<algo>/<method>`` -                  held-out
                                             ``standalone/<algo>``                  score
M   which aggregation method?                ``<algo>/<m1>`` - ``<algo>/<m2>``      own score
                                             (two-sided)
=== ======================================== ====================================== =========

The measure is the greedy score at the end of the run, in held-out evaluation episodes
(seeded random poses the learner never trained from) of the robot's own arena (L, F, M) or of
the arenas it never learnt in (T); collisions per 1,000 steps are shown beside it. The
**checks** are no question: each learning control minus the untrained table must include 0
(a control that cannot learn what L asks); L's rows of a condition whose control fails its
check, or has none, cannot be judged. Holm's correction runs within each question's family.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

#: The untrained table's condition, and the prefix of a learning control's.
UNTRAINED = "untrained"
CONTROL = "control/"
STANDALONE = "standalone/"
#: The off-policy reference's prefix (a diagnostic, no question uses it).
REFERENCE = "reference/"
#: The aggregation methods in the order M compares them.
METHODS = ("average", "max", "visit_average")
#: Default smallest effects of interest, in greedy-score units (a trained table scores about
#: 0.9 above the untrained one in the paper's arenas: 0.1 is a ninth of what learning gives).
DELTAS: Mapping[str, float] = {"L": 0.1, "F": 0.1, "T": 0.1, "M": 0.1}
TITLES: Mapping[str, str] = {
    "L": "Do the robots learn?",
    "F": "Does federation help in the robots' own arenas?",
    "T": "Do federated tables transfer better to arenas never learnt in?",
    "M": "Which aggregation method?",
    "C": "Checks: each learning control learns nothing (minus the untrained table includes 0)",
}


@dataclass(frozen=True)
class Row:
    """One contrast of a question: ``a - b`` on ``measure`` in ``role`` arenas."""

    question: str
    label: str
    a: str
    b: str
    role: str = "own"
    side: str = "above"
    measure: str = "score"


def trained_runs(runs: list[str]) -> list[str]:
    """Conditions that learnt from real rewards: neither a control, the reference, nor the
    untrained table."""
    return [
        r for r in runs if not (r == UNTRAINED or r.startswith(CONTROL) or r.startswith(REFERENCE))
    ]


def federated(run: str) -> tuple[str, str] | None:
    """(algo, method) of a federated condition, None for any other."""
    parts = run.split("/")
    if len(parts) == 2 and parts[0] not in ("standalone", "control", "reference"):
        return parts[0], parts[1]
    return None


def learning_rows(runs: list[str]) -> list[Row]:
    """L: every standalone condition and every federated condition with the ``average``
    method, against the untrained table and against its learning control."""
    out = []
    for r in trained_runs(runs):
        fed = federated(r)
        if not (r.startswith(STANDALONE) or (fed and fed[1] == "average")):
            continue
        out.append(Row("L", f"{r} - untrained", r, UNTRAINED))
        out.append(Row("L", f"{r} - its control", r, CONTROL + r))
    return out


def check_rows(runs: list[str]) -> list[Row]:
    """C: each learning control against the untrained table (two-sided)."""
    return [
        Row("C", f"{r} - untrained", r, UNTRAINED, side="two-sided")
        for r in runs
        if r.startswith(CONTROL)
    ]


def federation_rows(runs: list[str], question: str) -> list[Row]:
    """F (``own``) or T (``held_out``): every federated condition against the standalone
    condition of its algorithm."""
    role = "own" if question == "F" else "held_out"
    out = []
    for r in trained_runs(runs):
        fed = federated(r)
        if fed and STANDALONE + fed[0] in runs:
            out.append(
                Row(question, f"{r} - {STANDALONE}{fed[0]}", r, STANDALONE + fed[0], role=role)
            )
    return out


def method_rows(runs: list[str]) -> list[Row]:
    """M: every pair of methods run with one algorithm (two-sided)."""
    by_algo: dict[str, list[str]] = {}
    for r in trained_runs(runs):
        fed = federated(r)
        if fed:
            by_algo.setdefault(fed[0], []).append(fed[1])
    out = []
    for algo, methods in by_algo.items():
        known = [m for m in METHODS if m in methods] + sorted(set(methods) - set(METHODS))
        for i, m1 in enumerate(known):
            for m2 in known[i + 1 :]:
                out.append(
                    Row(
                        "M",
                        f"{algo}: {m1} - {m2}",
                        f"{algo}/{m1}",
                        f"{algo}/{m2}",
                        side="two-sided",
                    )
                )
    return out


def rows_for(runs: list[str]) -> dict[str, list[Row]]:
    """Every question's rows for the conditions present."""
    return {
        "C": check_rows(runs),
        "L": learning_rows(runs),
        "F": federation_rows(runs, "F"),
        "T": federation_rows(runs, "T"),
        "M": method_rows(runs),
    }
