"""Where references live: writing and verifying their files (``NAME.json`` sidecar with the
recipe, provenance and sha256 of ``NAME.q.npy`` and ``NAME.visits.npy``), and
:func:`reference_table`, which loads a reference from the cache or the shipped folder or builds
it (:mod:`.reference` holds what a reference is, its distance and how it is built).
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dfrl.experiments.science.reference import (
    DEFAULT_ITERATIONS,
    DEFAULT_MIN_VISITS,
    DEFAULT_SEEDS,
    REFERENCE_FORMAT,
    SHIPPED,
    Reference,
    ReferenceError,
    build_reference,
    default_cache,
    reference_name,
    reference_recipe,
)


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _files(folder: Path, name: str) -> tuple[Path, Path, Path]:
    return folder / f"{name}.json", folder / f"{name}.q.npy", folder / f"{name}.visits.npy"


def save_reference(reference: Reference, folder: str | Path) -> Path:
    """Write the three files into ``folder`` (created); the sidecar is written last, so a
    reference without one was never completed. Returns the sidecar's path."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    side, qf, vf = _files(folder, reference.name)
    np.save(qf, np.asarray(reference.q, dtype=np.float64))
    np.save(vf, np.stack([reference.visits, reference.runs]).astype(np.int64))
    meta = {
        "format": REFERENCE_FORMAT,
        "name": reference.name,
        "shape": list(reference.q.shape),
        "recipe": reference.recipe,
        "built": reference.built,
        "sha256": {qf.name: _sha256(qf), vf.name: _sha256(vf)},
    }
    tmp = side.with_suffix(".json.tmp")
    tmp.write_text(json.dumps(meta, indent=1) + "\n", encoding="utf-8")
    tmp.replace(side)
    return side


def load_reference(path: str | Path) -> Reference:
    """Read a stored reference (its sidecar ``NAME.json``) and verify it.

    Raises
    ------
    ReferenceError
        A file is missing or unreadable, the format is not ``dfrl-reference/1``, a checksum
        differs (the message names the file), or the arrays do not match the sidecar.
    """
    side = Path(path)
    try:
        meta = json.loads(side.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise ReferenceError(f"{side}: cannot read the reference sidecar ({exc})") from exc
    if not isinstance(meta, dict) or meta.get("format") != REFERENCE_FORMAT:
        raise ReferenceError(f"{side}: not a {REFERENCE_FORMAT} sidecar")
    name = meta.get("name", "")
    _, qf, vf = _files(side.parent, name)
    sums = meta.get("sha256", {})
    for f in (qf, vf):
        if not f.is_file():
            raise ReferenceError(f"{f}: missing (named by {side})")
        got = _sha256(f)
        if got != sums.get(f.name):
            raise ReferenceError(
                f"{f}: sha256 {got} differs from {sums.get(f.name)} recorded "
                f"in {side}; delete the reference's files to rebuild it"
            )
    q = np.load(qf, allow_pickle=False)
    vr = np.load(vf, allow_pickle=False)
    shape = tuple(meta.get("shape", ()))
    if q.shape != shape or vr.shape != (2, *shape):
        raise ReferenceError(f"{side}: arrays {q.shape}, {vr.shape} do not match shape {shape}")
    recipe = meta.get("recipe", {})
    if reference_name(recipe) != name:
        raise ReferenceError(f"{side}: the recipe does not give the name {name!r}")
    return Reference(
        q=q, visits=vr[0], runs=vr[1], recipe=recipe, built=meta.get("built", {}), path=side
    )


def reference_table(
    arena: str,
    algo: str = "qlearning",
    iterations: int = DEFAULT_ITERATIONS,
    seeds: Sequence[int] = tuple(range(1, DEFAULT_SEEDS + 1)),
    base: Any = None,
    cache: str | Path | None = None,
    min_visits: int = DEFAULT_MIN_VISITS,
    jobs: int = 1,
    rebuild: bool = False,
) -> Reference:
    """The reference of an arena: loaded (and verified) from the cache or, failing that,
    from the references shipped in :data:`SHIPPED`; else built into the cache.

    Parameters
    ----------
    arena, algo, iterations, seeds, base, min_visits
        The recipe (:func:`reference_recipe`).
    cache : str or Path, optional
        The folder (default :func:`default_cache`).
    jobs : int
        Processes for building.
    rebuild : bool
        Build into the cache even when the cache or the shipped folder holds it.

    Raises
    ------
    ReferenceError
        The cached copy fails verification (never silently rebuilt; ``rebuild=True`` does).
    ValueError
        A bad recipe.
    """
    recipe = reference_recipe(arena, algo, iterations, seeds, base, min_visits)
    folder = Path(cache) if cache is not None else default_cache()
    name = reference_name(recipe)
    for place in (folder, SHIPPED) if not rebuild else ():
        side, _, _ = _files(place, name)
        if side.is_file():
            ref = load_reference(side)
            if ref.recipe != recipe:
                raise ReferenceError(f"{side}: holds another recipe under the same name")
            return ref
    ref = build_reference(recipe, jobs=jobs)
    path = save_reference(ref, folder)
    return Reference(
        q=ref.q, visits=ref.visits, runs=ref.runs, recipe=ref.recipe, built=ref.built, path=path
    )
