"""Prints the imports between dfrl's rooms: who imports whom, and how many imports.

A room is a folder of ``experiments/`` (``cli``, ``science``, ``tools``, ``driver``,
``robot_host``), the shared modules at ``experiments/``'s top (``experiments.<top>``), or one of
the packages below (``robots``, ``pybridge``, ``arenas``, ``platform_pl``). Every import counts,
those inside functions and under ``TYPE_CHECKING`` too (grimp, the graph import-linter checks).
``python scripts/room_graph.py`` builds the checkout's link tree first (:mod:`link_tree`);
``--tree DIR`` reads a tree built elsewhere (``python scripts/link_tree.py OTHER_CHECKOUT DIR``).
"""

from __future__ import annotations

import argparse
import sys
from collections import Counter
from pathlib import Path

import grimp

sys.path.insert(0, str(Path(__file__).resolve().parent))
import link_tree  # noqa: E402

ROOMS = ("cli", "science", "tools", "driver", "robot_host")


def room(module: str) -> str:
    """The room of a module name of ``dfrl``."""
    parts = module.split(".")
    if len(parts) < 2:
        return "dfrl"
    if parts[1] != "experiments" or len(parts) < 3:
        return parts[1]
    if parts[2] == "__main__":
        return "experiments.__main__"
    return f"experiments.{parts[2] if parts[2] in ROOMS else '<top>'}"


def edges(package: str = "dfrl") -> Counter[tuple[str, str]]:
    """(importer's room, imported room) -> number of import lines, rooms importing themselves
    left out."""
    graph = grimp.build_graph(package, cache_dir=None)
    found: Counter[tuple[str, str]] = Counter()
    for importer in graph.modules:
        for imported in graph.find_modules_directly_imported_by(importer):
            pair = (room(importer), room(imported))
            if pair[0] != pair[1]:
                lines = graph.get_import_details(importer=importer, imported=imported)
                found[pair] += max(1, len(lines))
    return found


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="imports between dfrl's rooms")
    parser.add_argument("--tree", type=Path, help="a link tree (default: build the checkout's)")
    args = parser.parse_args(argv)
    tree = args.tree
    if tree is None:
        root = Path(__file__).resolve().parent.parent
        tree = link_tree.build(root, root / "build" / "typecheck").parent
    sys.path.insert(0, str(tree.resolve()))
    found = edges()
    for (source, target), count in sorted(found.items()):
        back = " (cycle)" if (target, source) in found else ""
        print(f"{source:24} -> {target:24} {count:4}{back}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
