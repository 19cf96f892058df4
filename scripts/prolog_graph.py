"""The load graph of the Prolog sources: load cycles, and platform modules that name dFRL.

Reads every ``.pl`` file under the given folders (default ``platform_pl`` and ``pybridge``),
whatever their layout, and takes the files each one loads by a directive (``use_module``,
``ensure_loaded``, ``reexport``, ``consult``, ``load_files``; a plain or quoted file name,
relative to the loading file, or a list of them; ``library(...)`` and other aliases are not
ours and are left out). Two findings, each naming its files:

* a load cycle: files that load each other, directly or through others (each cycle once);
* a module of the platform (a ``.pl`` with ``:- module`` under ``platform_pl/``, outside
  ``platform_pl/dfrl_agent/``) that names the dFRL application: it loads a file of
  ``dfrl_agent/``, or qualifies a goal or a predicate indicator with one of its modules
  (``dfrl_aggregation:aggregate_init/3``). Comments and quoted text do not count;
* a module longer than ``--max-lines`` lines (default 500: split it by responsibility).

Each finding is one line, naming its file(s). Exits 1 if there is a finding, 0 if not
(``--warn``: 0 either way, the findings printed all the same). Usage:
``python scripts/prolog_graph.py [--root DIR] [--edges] [--warn] [--max-lines N] [FOLDER ...]``
(``--edges`` also prints every load edge).
"""

from __future__ import annotations

import argparse
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

LOADERS = ("use_module", "ensure_loaded", "reexport", "consult", "load_files")
APP_DIR = Path("platform_pl") / "dfrl_agent"
PLATFORM_DIR = Path("platform_pl")


def _skip_quoted(text: str, i: int, quote: str) -> int:
    """The index after the quoted item that starts at ``text[i] == quote``."""
    i += 1
    while i < len(text):
        c = text[i]
        if c == "\\":
            i += 2
            continue
        if c == quote:
            if text[i + 1 : i + 2] == quote:  # a doubled quote stands for one
                i += 2
                continue
            return i + 1
        i += 1
    return i


def clauses(text: str) -> list[tuple[str, str]]:
    """The clauses of a source, each as (text without comments, the same with quoted items
    blanked out). A clause ends at a full stop followed by layout or the end."""
    out: list[tuple[str, str]] = []
    kept: list[str] = []
    blank: list[str] = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if c == "%":
            i = text.find("\n", i)
            i = n if i < 0 else i
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            i = n if j < 0 else j + 2
            kept.append(" ")
            blank.append(" ")
        elif text.startswith("0'", i) and i + 2 < n:  # a character code: 0'a, 0''', 0'\n
            j = i + 3
            if text[i + 2] == "\\" or text.startswith("''", i + 2):
                j = i + 4
            kept.append(" ")
            blank.append(" ")
            i = j
        elif c in "'\"`":
            j = _skip_quoted(text, i, c)
            kept.append(text[i:j])
            blank.append(" ")
            i = j
        elif c == "." and (i + 1 == n or text[i + 1].isspace() or text[i + 1] == "%"):
            out.append(("".join(kept).strip(), "".join(blank).strip()))
            kept, blank = [], []
            i += 1
        else:
            kept.append(c)
            blank.append(c)
            i += 1
    return out


def _top_args(text: str) -> list[str]:
    """The comma-separated items of ``text`` at bracket depth 0."""
    items, depth, start = [], 0, 0
    for k, c in enumerate(text):
        if c in "([{":
            depth += 1
        elif c in ")]}":
            depth -= 1
        elif c == "," and depth == 0:
            items.append(text[start:k])
            start = k + 1
    items.append(text[start:])
    return [s.strip() for s in items if s.strip()]


def _first_arg(text: str) -> str:
    """The first argument of the call that ``text`` starts just inside of."""
    depth = 0
    for k, c in enumerate(text):
        if c in "([{":
            depth += 1
        elif c in ")]}":
            if depth == 0:
                return text[:k]
            depth -= 1
        elif c == "," and depth == 0:
            return text[:k]
    return text


def load_specs(clause: str) -> list[str]:
    """The file specifications a directive loads (``:- use_module(node, [...])`` -> node)."""
    if not clause.startswith(":-"):
        return []
    specs: list[str] = []
    for m in re.finditer(rf"\b({'|'.join(LOADERS)})\s*\(", clause):
        arg = _first_arg(clause[m.end() :]).strip()
        items = _top_args(arg[1:-1]) if arg.startswith("[") and arg.endswith("]") else [arg]
        specs += items
    return specs


def resolve(spec: str, source: Path) -> Path | None:
    """The file a specification names, relative to the loading file (None: an alias such as
    ``library(...)``, a variable, or nothing there)."""
    if len(spec) > 1 and spec[0] == spec[-1] == "'":
        spec = spec[1:-1].replace("''", "'")
    elif not re.fullmatch(r"[a-z][A-Za-z0-9_]*(/[a-z][A-Za-z0-9_]*)*", spec):
        return None
    base = source.parent / spec
    for candidate in (base.with_name(base.name + ".pl"), base):
        if candidate.is_file():
            return candidate.resolve()
    return None


@dataclass
class PlFile:
    path: Path
    module: str | None
    loads: list[Path] = field(default_factory=list)
    qualifiers: set[str] = field(default_factory=set)
    lines: int = 0


def read_file(path: Path) -> PlFile:
    """A source's module name, the files it loads and the module qualifiers it uses."""
    text = path.read_text(encoding="utf-8", errors="replace")
    module = None
    item = PlFile(path.resolve(), None, lines=len(text.splitlines()))
    for kept, blank in clauses(text):
        m = re.match(r":-\s*module\(\s*([a-z][A-Za-z0-9_]*)", kept)
        if m and module is None:
            module = item.module = m.group(1)
        for spec in load_specs(kept):
            target = resolve(spec, path)
            if target is not None:
                item.loads.append(target)
        item.qualifiers |= set(
            re.findall(r"(?<![A-Za-z0-9_])([a-z][A-Za-z0-9_]*)\s*:(?![-=])", blank)
        )
    return item


def cycles(files: dict[Path, PlFile]) -> list[list[Path]]:
    """The strongly connected components with more than one file (or a file loading itself),
    each sorted (Tarjan's algorithm, iterative)."""
    index: dict[Path, int] = {}
    low: dict[Path, int] = {}
    stack: list[Path] = []
    on_stack: set[Path] = set()
    found: list[list[Path]] = []
    counter = 0
    for start in sorted(files):
        if start in index:
            continue
        work = [(start, 0)]
        while work:
            node, k = work.pop()
            if k == 0:
                index[node] = low[node] = counter
                counter += 1
                stack.append(node)
                on_stack.add(node)
            succ = [t for t in files[node].loads if t in files]
            if k < len(succ):
                work.append((node, k + 1))
                nxt = succ[k]
                if nxt not in index:
                    work.append((nxt, 0))
                elif nxt in on_stack:
                    low[node] = min(low[node], index[nxt])
                continue
            if low[node] == index[node]:
                comp = []
                while True:
                    top = stack.pop()
                    on_stack.discard(top)
                    comp.append(top)
                    if top == node:
                        break
                if len(comp) > 1 or node in files[node].loads:
                    found.append(sorted(comp))
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
    return found


def app_names(files: dict[Path, PlFile], root: Path) -> list[str]:
    """The findings ``platform module names the dFRL application``, one line each."""
    app_dir = (root / APP_DIR).resolve()
    platform = (root / PLATFORM_DIR).resolve()
    app = {f.path for f in files.values() if f.path.is_relative_to(app_dir)}
    app_modules = {f.module for f in files.values() if f.path in app and f.module}
    out = []
    for f in sorted(files.values(), key=lambda f: f.path):
        if not f.path.is_relative_to(platform) or f.path in app or f.module is None:
            continue
        loads = sorted(_rel(t, root) for t in f.loads if t in app)
        named = sorted(f.qualifiers & app_modules)
        if loads or named:
            what = [f"loads {', '.join(loads)}"] if loads else []
            what += [f"qualifies with {', '.join(named)}"] if named else []
            out.append(
                f"{_rel(f.path, root)}: platform module {f.module} names the dFRL "
                f"application ({'; '.join(what)})"
            )
    return out


def _rel(path: Path, root: Path) -> str:
    try:
        return path.relative_to(root.resolve()).as_posix()
    except ValueError:
        return str(path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=Path(__file__).resolve().parent.parent)
    parser.add_argument("--edges", action="store_true", help="print every load edge too")
    parser.add_argument(
        "--warn", action="store_true", help="report the findings without failing (exit 0)"
    )
    parser.add_argument(
        "--max-lines",
        type=int,
        default=500,
        help="the longest a module may be (default: %(default)s)",
    )
    parser.add_argument("folders", nargs="*", default=["platform_pl", "pybridge"])
    args = parser.parse_args(argv)
    root = args.root.resolve()
    missing = [d for d in args.folders if not (root / d).is_dir()]
    paths = sorted(p for d in args.folders for p in (root / d).rglob("*.pl"))
    if missing or not paths:  # a check that read nothing must not pass
        print(
            f"prolog_graph: no Prolog sources read under {root} "
            f"(missing folders: {', '.join(missing) or 'none'})",
            file=sys.stderr,
        )
        return 2
    files = {f.path: f for f in map(read_file, paths)}
    if args.edges:
        for f in sorted(files.values(), key=lambda f: f.path):
            for t in f.loads:
                print(f"{_rel(f.path, root)} -> {_rel(t, root)}")
    findings = [
        f"load cycle: {', '.join(_rel(p, root) for p in comp)} load each other"
        for comp in cycles(files)
    ]
    findings += app_names(files, root)
    findings += [
        f"{_rel(f.path, root)}: module {f.module} has {f.lines} lines, over {args.max_lines}"
        for f in sorted(files.values(), key=lambda f: f.path)
        if f.module is not None and f.lines > args.max_lines
    ]
    for line in findings:
        print(line)
    print(
        f"prolog_graph: {len(files)} files, "
        f"{sum(len(f.loads) for f in files.values())} load edges, {len(findings)} findings",
        file=sys.stderr,
    )
    return 1 if findings and not args.warn else 0


if __name__ == "__main__":
    sys.exit(main())
