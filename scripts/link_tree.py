"""Builds the package tree that static tools read: ``dfrl/`` with the project's folders inside.

In a checkout ``dfrl.robots`` is the folder ``robots/`` beside ``dfrl/`` (``dfrl/__init__.py``
extends its ``__path__`` at import time; setup.py maps the folders for a wheel). mypy and
import-linter do not run that code: they look for ``dfrl/robots/`` on their search path. This
script makes ``OUT/dfrl/``: symbolic links to ``dfrl/``'s own files and to each folder of
setup.py's ``ROOTS``, so both tools read the checkout's files, new files included, without a
copy. ``OUT`` is rebuilt on every call (a folder that disappeared leaves no stale link).

Usage: ``python scripts/link_tree.py [ROOT [OUT]]`` (defaults: the checkout, ``build/typecheck``).
"""

from __future__ import annotations

import ast
import shutil
import sys
from pathlib import Path


def roots(project: Path) -> tuple[str, ...]:
    """The folders that become ``dfrl.<folder>``: setup.py's ``ROOTS``, read without running it."""
    tree = ast.parse((project / "setup.py").read_text(encoding="utf-8"))
    for node in tree.body:
        if isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            if any(isinstance(t, ast.Name) and t.id == "ROOTS" for t in targets):
                assert node.value is not None
                return tuple(ast.literal_eval(node.value))
    raise SystemExit(f"link_tree: no ROOTS in {project / 'setup.py'}")


def build(project: Path, out: Path) -> Path:
    """Makes ``out/dfrl`` (links into ``project``) and returns it."""
    package = out / "dfrl"
    if out.exists():
        shutil.rmtree(out)
    package.mkdir(parents=True)
    for item in sorted((project / "dfrl").iterdir()):
        if item.name != "__pycache__":
            (package / item.name).symlink_to(item.resolve())
    for folder in roots(project):
        (package / folder).symlink_to((project / folder).resolve(), target_is_directory=True)
    return package


def main(argv: list[str]) -> int:
    project = Path(argv[0] if argv else Path(__file__).resolve().parent.parent).resolve()
    out = Path(argv[1]) if len(argv) > 1 else project / "build" / "typecheck"
    build(project, out)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
