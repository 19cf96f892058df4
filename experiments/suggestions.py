""" "Did you mean": the known names closest to a misspelt one, for every message that refuses an
unknown key or value (config keys, algorithms, methods, itineraries, arenas, ...).

The distance is Damerau-Levenshtein in its optimal-string-alignment form
(:func:`edit_distance`): one letter dropped, added, changed, or two neighbours swapped, each
cost 1 (``iteratons`` -> ``iterations``, ``qlearing`` -> ``qlearning``, ``sarsa`` ->
``sasra``: all 1), compared without case. A name is suggested (:func:`near_names`) when it is
at most :func:`allowed_distance` edits away (1 for names under 6 letters, 2 from 6 on: one
slip is always caught, two in a long word too, and a short word is not matched to an
unrelated one), or when one of the two names begins with the other and the shorter has at
least 3 letters (``algorithm`` -> ``algo``). Only the nearest names are offered, and only when
at most :data:`MAX_SUGGESTIONS` of them are that near: ``r9`` is one edit from each of
``r1`` .. ``r5`` and nothing tells which was meant, so none is offered (the message lists the
known names anyway).

Why not :func:`difflib.get_close_matches`: its ratio counts matching blocks, so a swap of two
letters costs as much as two changes, and no single cutoff both catches one slip in a
3-letter name and rejects unrelated 8-letter names; an edit count states the rule directly.
"""

from __future__ import annotations

from collections.abc import Iterable

__all__ = ["MAX_SUGGESTIONS", "allowed_distance", "did_you_mean", "edit_distance", "near_names"]

#: More names equally near than this: no suggestion (ambiguous).
MAX_SUGGESTIONS = 3


def edit_distance(a: str, b: str) -> int:
    """Optimal-string-alignment distance between ``a`` and ``b``: the fewest deletions,
    insertions, substitutions and swaps of two adjacent characters (no substring edited
    twice) that turn one into the other. Case matters (callers lower-case)."""
    if a == b:
        return 0
    prev2: list[int] = []
    prev = list(range(len(b) + 1))
    for i in range(1, len(a) + 1):
        row = [i] + [0] * len(b)
        for j in range(1, len(b) + 1):
            cost = 0 if a[i - 1] == b[j - 1] else 1
            row[j] = min(prev[j] + 1, row[j - 1] + 1, prev[j - 1] + cost)
            if i > 1 and j > 1 and a[i - 1] == b[j - 2] and a[i - 2] == b[j - 1]:
                row[j] = min(row[j], prev2[j - 2] + 1)
        prev2, prev = prev, row
    return prev[-1]


def allowed_distance(word: str) -> int:
    """Edits a misspelling of a name as long as ``word`` may have and still be matched."""
    return 1 if len(word) < 6 else 2


def near_names(word: str, known: Iterable[str]) -> list[str]:
    """The names of ``known`` that ``word`` most likely misspells, nearest first (at most
    :data:`MAX_SUGGESTIONS`; empty when none is near or too many are equally near)."""
    w = word.lower()
    scored: dict[str, float] = {}
    for name in known:
        n = name.lower()
        if n == w:
            continue
        limit = allowed_distance(w)
        # the length difference bounds the distance from below: no table for names too long
        d: float = edit_distance(w, n) if abs(len(w) - len(n)) <= limit else limit + 1
        if d > limit:
            short, long_ = sorted((w, n), key=len)
            if len(short) < 3 or not long_.startswith(short):
                continue
            d = limit + 0.5  # a prefix: after every near spelling
        scored.setdefault(name, d)
    if not scored:
        return []
    best = min(scored.values())
    nearest = [name for name, d in scored.items() if d == best]
    return sorted(nearest) if len(nearest) <= MAX_SUGGESTIONS else []


def did_you_mean(word: object, known: Iterable[str]) -> str:
    """``"did you mean 'x'?"`` (or ``'x' or 'y'``) for ``word`` among ``known``; ``""`` when
    ``word`` is no string or nothing is near."""
    if not isinstance(word, str):
        return ""
    names = [repr(n) for n in near_names(word, known)]
    if not names:
        return ""
    said = names[0] if len(names) == 1 else f"{', '.join(names[:-1])} or {names[-1]}"
    return f"did you mean {said}?"
