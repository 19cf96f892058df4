#!/usr/bin/env bash
# Installs what is missing for dfrl, and nothing more: SWI-Prolog from Debian's packages (and
# a C compiler, to build the platform's three foreign libraries),
# a virtual environment in .venv, and the dfrl package with its dependencies. Safe to run
# again: each step checks first. Source it (`. scripts/setup.sh`) or run it.
set -euo pipefail

DFRL_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${DFRL_VENV:-$DFRL_ROOT/.venv}"

say() { printf '[setup] %s\n' "$*" >&2; }

as_root() {
    if [ "$(id -u)" -eq 0 ]; then "$@"; else sudo "$@"; fi
}

if ! command -v swipl >/dev/null 2>&1; then
    say "installing SWI-Prolog (swi-prolog-nox) from Debian's packages"
    as_root apt-get update -qq
    DEBIAN_FRONTEND=noninteractive as_root apt-get install -y -qq swi-prolog-nox >/dev/null
fi

# The platform's foreign libraries (platform_pl/native): a C compiler for swipl-ld.
if ! command -v cc >/dev/null 2>&1; then
    say "installing a C compiler (gcc) for the platform's foreign libraries"
    as_root apt-get update -qq
    DEBIAN_FRONTEND=noninteractive as_root apt-get install -y -qq gcc libc6-dev >/dev/null
fi
bash "$DFRL_ROOT/platform_pl/native/build.sh"

PYTHON="${PYTHON:-python3}"
if [ ! -x "$VENV/bin/python" ]; then
    say "creating the virtual environment $VENV"
    if ! "$PYTHON" -m venv "$VENV" 2>/dev/null; then
        say "python3 venv is missing; installing python3-venv"
        as_root apt-get update -qq
        DEBIAN_FRONTEND=noninteractive as_root apt-get install -y -qq python3-venv >/dev/null
        "$PYTHON" -m venv "$VENV"
    fi
fi

# Reinstall only when the project's metadata (pyproject.toml, setup.py) changed since the last
# install.
stamp="$VENV/.dfrl-installed"
want="$(cat "$DFRL_ROOT/pyproject.toml" "$DFRL_ROOT/setup.py" | sha256sum | cut -d' ' -f1)"
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ] \
        || ! "$VENV/bin/python" -c 'import pybullet, pyswip, gymnasium, matplotlib, pytest, autograd, statsmodels, rliable' 2>/dev/null; then
    say "installing the dfrl package and its dependencies into $VENV"
    "$VENV/bin/python" -m pip install -q --upgrade pip >/dev/null
    "$VENV/bin/python" -m pip install -q -e "$DFRL_ROOT[dev,science]"
    echo "$want" > "$stamp"
fi

export PATH="$VENV/bin:$PATH"
export VIRTUAL_ENV="$VENV"
