"""``dfrl paper --sim batched --confirm-seeds K``: the batched paper's contrasts of questions
F and T (does federation help, do federated tables transfer) run again on pybullet with the
study's first K seeds (the in-process replicas of ``dfrl paper``, into ``OUT/confirm_pybullet``),
each row compared with the rule of the other studies' confirmations
(:data:`.studies.confirm.RULE`: the pybullet 95% interval contains the batched estimate, or the
verdicts are the same).
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path
from typing import TextIO

from dfrl.experiments.science.questions.answers import Answers
from dfrl.experiments.science.reproduce import PaperOptions, _seeds, reproduce_paper
from dfrl.experiments.science.studies.confirm import RULE, Confirmation, Estimate, disagreeing

#: The questions confirmed: the paper's headline claims.
CONFIRMED = ("F", "T")
#: Where the pybullet runs go, inside the batched study's folder.
FOLDER = "confirm_pybullet"


def estimates(ans: Answers) -> dict[str, Estimate]:
    """Each row of :data:`CONFIRMED` as an :class:`Estimate` (name ``"F: A - B"``)."""
    out = {}
    for q in CONFIRMED:
        for a in ans.questions.get(q, []):
            c = a.judged.contrast
            low, high = c.interval()
            out[f"{q}: {a.row.label}"] = Estimate(
                c.estimate, low, high, c.n, a.judged.words(), (a.judged.outcome.value,)
            )
    return out


def confirm_paper(
    out: Path, opts: PaperOptions, batched: Answers, seeds: int, progress: TextIO | None = None
) -> list[Confirmation]:
    """Run the pybullet paper on the first ``seeds`` seeds of ``opts`` and compare; writes
    ``OUT/confirmation.json``."""
    first = tuple(_seeds(opts)[:seeds])
    rep = reproduce_paper(Path(out) / FOLDER, replace(opts, seeds=first), progress)
    ours, theirs = estimates(batched), estimates(rep.answers)
    found = [Confirmation(name, ours[name], theirs[name]) for name in ours if name in theirs]
    (Path(out) / "confirmation.json").write_text(
        json.dumps(
            {"seeds": list(first), "rule": RULE, "contrasts": [c.to_dict() for c in found]},
            indent=2,
        )
        + "\n",
        encoding="utf-8",
    )
    return found


def markdown(found: list[Confirmation], seeds: int) -> list[str]:
    """The report's "Confirmation in pybullet" section."""
    bad = disagreeing(found)
    head = (
        f"**{len(bad)} of {len(found)} contrasts disagree**: " + ", ".join(c.contrast for c in bad)
        if bad
        else f"All {len(found)} contrasts agree"
    )
    lines = [
        "",
        "## Confirmation in pybullet",
        "",
        f"{head} ({RULE}; pybullet on the first {seeds} seeds, `{FOLDER}/`).",
        "",
        "| contrast | batched [95%] | pybullet [95%] | agrees |",
        "|---|---|---|---|",
    ]
    for c in found:
        lines.append(
            f"| {c.contrast} | {_shown(c.batched)} | {_shown(c.pybullet)} | "
            f"{'yes' if c.agrees else '**no**'} |"
        )
    return lines


def _shown(e: Estimate) -> str:
    if math.isnan(e.low):
        return f"{e.estimate:+.3f} (n = {e.n}; {e.verdict})"
    return f"{e.estimate:+.3f} [{e.low:+.3f}, {e.high:+.3f}] (n = {e.n}; {e.verdict})"
