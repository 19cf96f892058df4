"""Run the fidelity checks and say what they mean for the studies."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from dfrl.experiments.science.fidelity.learning import LearningCheck, check_learning
from dfrl.experiments.science.fidelity.policies import compare_policies
from dfrl.experiments.science.fidelity.sensing import compare_sensing, compare_transitions
from dfrl.experiments.science.pool import stop_pool, study_pool
from dfrl.robots.batched.training import env_part
from dfrl.robots.training import TrainerConfig

#: Tolerances the report states for the checks before the decisive one.
SENSING_P99_MM: float = 1.0  # 99% of IR readings within 1 mm
TRANSITION_TV: float = 0.05  # next-state distributions within 0.05 (total variation)
COLLISION_DIFF: float = 1.0  # fixed policies: within 1 collision per 1,000 steps
PROGRESS_DIFF: float = 0.05  # and within 0.05 of progress

#: What each check being out of tolerance affects.
AFFECTS: dict[str, str] = {
    "sensing": "every study (states and the near-contact penalty come from the IR readings)",
    "transitions": "every study (what a table learns is the state-action outcomes)",
    "policies": "dfrl transfer-study and the paper's collisions per 1,000 steps",
    "learning": "every study's scores: confirm its headline contrasts in pybullet (--sim pybullet)",
}


@dataclass(frozen=True)
class FidelityOptions:
    """What ``dfrl bench sim-fidelity`` runs."""

    arenas: tuple[str, ...] = ("r1", "r4")
    poses: int = 2000
    transitions: int = 6000
    policy_steps: int = 20_000
    learning: LearningCheck = field(default_factory=LearningCheck)
    seed: int = 1
    workers: int = 2
    checks: tuple[str, ...] = ("sensing", "transitions", "policies", "learning")


def _verdicts(arena: dict[str, Any]) -> dict[str, bool]:
    out: dict[str, bool] = {}
    if "sensing" in arena:
        out["sensing"] = arena["sensing"]["p99_abs_mm"] <= SENSING_P99_MM
    if "transitions" in arena:
        out["transitions"] = arena["transitions"]["tv_distance"] <= TRANSITION_TV
    if "policies" in arena:
        out["policies"] = all(
            abs(p["collisions_difference"][0]) <= COLLISION_DIFF
            and abs(p["progress_difference"][0]) <= PROGRESS_DIFF
            for p in arena["policies"].values()
        )
    if "learning" in arena:
        out["learning"] = arena["learning"]["holds"]
    return out


def run(opts: FidelityOptions, progress: Callable[[str], None] | None = None) -> dict[str, Any]:
    """Every check of ``opts.checks`` in every arena; one JSON-ready dict."""
    say = progress or (lambda _: None)
    base = TrainerConfig()
    env = env_part(base)
    t0 = time.perf_counter()
    arenas: dict[str, Any] = {}
    pool = study_pool(opts.workers) if "learning" in opts.checks else None
    try:
        for arena in opts.arenas:
            out: dict[str, Any] = {}
            cfg = env.__class__(**{**env.__dict__, "arena": arena})
            if "sensing" in opts.checks:
                say(f"{arena}: sensing at {opts.poses} poses")
                out["sensing"] = compare_sensing(cfg, arena, opts.poses, opts.seed)
            if "transitions" in opts.checks:
                say(f"{arena}: {opts.transitions} transitions")
                out["transitions"] = compare_transitions(cfg, arena, opts.transitions, opts.seed)
            if "policies" in opts.checks:
                say(f"{arena}: fixed policies, {opts.policy_steps} steps each")
                out["policies"] = compare_policies(cfg, arena, opts.policy_steps, opts.seed)
            if pool is not None:
                say(
                    f"{arena}: learning, {opts.learning.seeds} seeds x {opts.learning.tables} "
                    f"tables per simulator"
                )
                out["learning"] = check_learning(base, arena, opts.learning, pool)
            out["within_tolerance"] = _verdicts(out)
            out["affects"] = [AFFECTS[k] for k, ok in out["within_tolerance"].items() if not ok]
            arenas[arena] = out
    finally:
        if pool is not None:
            stop_pool(pool)
    return {
        "benchmark": "sim-fidelity",
        "options": asdict(opts),
        "arenas": arenas,
        "tolerances": {
            "sensing_p99_mm": SENSING_P99_MM,
            "transition_tv": TRANSITION_TV,
            "collisions_per_1000": COLLISION_DIFF,
            "progress": PROGRESS_DIFF,
            "learning_margin": opts.learning.margin,
        },
        "holds": all(all(a["within_tolerance"].values()) for a in arenas.values()),
        "wall_s": round(time.perf_counter() - t0, 1),
    }


def _mark(ok: bool) -> str:
    return "within" if ok else "OUTSIDE"


def render(result: dict[str, Any]) -> str:
    """The report as markdown."""
    lines = ["# Batched simulator against pybullet", ""]
    for name, a in result["arenas"].items():
        ok = a["within_tolerance"]
        lines.append(f"## {name}")
        if "sensing" in a:
            s = a["sensing"]
            lines.append(
                f"- IR readings ({s['readings']}): mean {s['mean_abs_mm']:.3f} mm, 99% "
                f"within {s['p99_abs_mm']:.2f} mm, largest {s['max_abs_mm']:.1f} mm; same "
                f"state at {s['state_agreement']:.1%} of poses ({_mark(ok['sensing'])})"
            )
        if "transitions" in a:
            t = a["transitions"]
            lines.append(
                f"- transitions ({t['transitions']}): same next state "
                f"{t['agreement']:.1%}; total variation {t['tv_distance']:.3f} (floor "
                f"between two batched replays {t['tv_floor']:.3f}) "
                f"({_mark(ok['transitions'])})"
            )
        for pol, p in a.get("policies", {}).items():
            c, g = p["collisions_difference"], p["progress_difference"]
            lines.append(
                f"- policy {pol}: collisions/1000 pybullet "
                f"{p['pybullet']['collisions_per_1000']:.2f}, batched "
                f"{p['batched']['collisions_per_1000']:.2f} "
                f"(diff {c[0]:+.2f} ± {c[1]:.2f}); progress "
                f"{p['pybullet']['progress']:.3f} vs {p['batched']['progress']:.3f} "
                f"(diff {g[0]:+.3f} ± {g[1]:.3f})"
            )
        if "learning" in a:
            le = a["learning"]
            lines.append(
                f"- **learning** ({le['seeds']} seeds x {le['tables_per_seed']} tables, "
                f"{le['iterations']} iterations): in pybullet, batched-learnt "
                f"{le['batched_learnt_in_pybullet']:.3f}, pybullet-learnt "
                f"{le['pybullet_learnt_in_pybullet']:.3f}; difference "
                f"{le['difference']:+.3f} [{le['interval'][0]:+.3f}, "
                f"{le['interval'][1]:+.3f}], margin ±{le['margin']} "
                f"({'holds' if le['holds'] else 'does NOT hold'}); batched-learnt in "
                f"batched {le['batched_learnt_in_batched']:.3f}"
            )
        for text in a["affects"]:
            lines.append(f"- affects: {text}")
        lines.append("")
    lines.append(
        f"All checks within tolerance: {'yes' if result['holds'] else 'NO'} ({result['wall_s']} s)"
    )
    return "\n".join(lines) + "\n"


def write(result: dict[str, Any], out: Path) -> None:
    """``fidelity.json`` and ``fidelity.md`` in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "fidelity.json").write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    (out / "fidelity.md").write_text(render(result), encoding="utf-8")
