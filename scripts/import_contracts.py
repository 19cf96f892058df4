"""import-linter over the checkout: the contracts of ``[tool.importlinter]`` in pyproject.toml.

import-linter finds ``dfrl.robots`` where Python would without running ``dfrl/__init__.py``:
in a folder ``dfrl/robots/``. So this builds the link tree (:mod:`link_tree`) and runs
``lint-imports`` from inside it (it puts its working folder first on ``sys.path``, where the
tree's ``dfrl`` then shadows the checkout's). Exits with lint-imports' status (0: every contract
kept). Usage: ``python scripts/import_contracts.py [--root DIR]``.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import link_tree  # noqa: E402


def main(argv: list[str]) -> int:
    root = Path(__file__).resolve().parent.parent
    if argv[:1] == ["--root"]:
        root = Path(argv[1]).resolve()
    tree = root / "build" / "typecheck"
    link_tree.build(root, tree)
    exe = shutil.which("lint-imports", path=str(Path(sys.executable).parent)) or "lint-imports"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    done = subprocess.run(
        [exe, "--no-cache", str(root / "pyproject.toml")], cwd=tree, env=env, check=False
    )
    return done.returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
