#!/usr/bin/env bash
# The gates CI runs before the tests: ruff (lint, and the layout `ruff format` gives), mypy
# (types), import-linter (the import arrows between packages and rooms) and the Prolog load
# graph. Installs what is missing (the extra "dev" holds the tools), runs every gate even after
# one failed, and exits 1 if any found something. Settings: pyproject.toml ([tool.ruff],
# [tool.mypy], [tool.importlinter]).
#
# The Prolog gate (scripts/prolog_graph.py): load cycles, platform modules naming the dFRL
# application, modules over 500 lines.
set -euo pipefail
. "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
cd "$DFRL_ROOT"

python -c 'import mypy, importlinter, ruff' 2>/dev/null \
    || python -m pip install -q -e "$DFRL_ROOT[dev]"

# the package folders the gates read (tests/ get ruff's lighter selection, see pyproject.toml)
PACKAGES=(platform_pl pybridge robots arenas experiments dfrl scripts tests)
failed=()
gate() {   # gate NAME COMMAND...: run one gate, say its verdict, remember a failure
    local name="$1"; shift
    local start=$SECONDS
    echo "[gates] $name: $*" >&2
    if "$@"; then
        echo "[gates] $name: passed ($((SECONDS - start)) s)" >&2
    else
        echo "[gates] $name: FAILED ($((SECONDS - start)) s)" >&2
        failed+=("$name")
    fi
}

gate ruff ruff check --no-cache "${PACKAGES[@]}"
gate ruff-format ruff format --check --no-cache "${PACKAGES[@]}"
gate mypy python scripts/typecheck.py
gate import-linter python scripts/import_contracts.py
gate prolog-graph python scripts/prolog_graph.py

if [ ${#failed[@]} -gt 0 ]; then
    echo "[gates] failed: ${failed[*]}" >&2
    exit 1
fi
echo "[gates] all passed" >&2
