"""mypy over the ``dfrl`` package of a checkout, its findings naming the checkout's files.

Builds the link tree (:mod:`link_tree`: ``build/typecheck/dfrl`` -> the folders), runs mypy with
the checkout's ``pyproject.toml`` (``[tool.mypy]``: ``mypy_path`` is that tree, the cache is
``build/mypy_cache``) and rewrites ``build/typecheck/dfrl/robots/x.py`` in its output to
``robots/x.py``. Exits with mypy's status (0: no error).

Usage: ``python scripts/typecheck.py [--root DIR] [MYPY_ARGS...]``.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import link_tree  # noqa: E402


def real_paths(text: str, tree: str, folders: tuple[str, ...]) -> str:
    """``text`` with the tree's paths (``TREE/dfrl/robots/...``) as the checkout's."""
    names = "|".join(re.escape(f) for f in folders)
    text = re.sub(rf"{re.escape(tree)}/dfrl/({names})/", r"\1/", text)
    return text.replace(f"{tree}/dfrl/", "dfrl/")


def main(argv: list[str]) -> int:
    root = Path(__file__).resolve().parent.parent
    if argv[:1] == ["--root"]:
        root, argv = Path(argv[1]).resolve(), argv[2:]
    tree = "build/typecheck"
    link_tree.build(root, root / tree)
    cmd = [sys.executable, "-m", "mypy", "--config-file", str(root / "pyproject.toml"), *argv]
    done = subprocess.run(
        cmd,
        cwd=root,
        capture_output=True,
        text=True,
        check=False,
        env={**os.environ, "MYPY_FORCE_COLOR": "0"},
    )
    folders = link_tree.roots(root)
    sys.stdout.write(real_paths(done.stdout, tree, folders))
    sys.stderr.write(real_paths(done.stderr, tree, folders))
    return done.returncode


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
