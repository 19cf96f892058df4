#!/usr/bin/env bash
# Installs what the live view's browser test needs and nothing more: Chromium and its
# WebDriver from Debian's packages (chromium, chromium-driver), and selenium in the virtual
# environment when it is missing. Safe to run again: each step checks first. Prints the
# paths of the browser and the driver on stdout (`chromium=PATH`, `chromedriver=PATH`).
set -euo pipefail

DFRL_ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${DFRL_VENV:-$DFRL_ROOT/.venv}"

say() { printf '[browser-setup] %s\n' "$*" >&2; }

as_root() {
    if [ "$(id -u)" -eq 0 ]; then "$@"; else sudo "$@"; fi
}

find_browser() {
    command -v chromium 2>/dev/null || command -v chromium-browser 2>/dev/null || true
}

find_driver() {
    command -v chromedriver 2>/dev/null \
        || { [ -x /usr/lib/chromium/chromedriver ] && echo /usr/lib/chromium/chromedriver; } \
        || true
}

if [ -z "$(find_browser)" ] || [ -z "$(find_driver)" ]; then
    say "installing chromium and chromium-driver from Debian's packages"
    as_root apt-get update -qq
    DEBIAN_FRONTEND=noninteractive as_root apt-get install -y -qq --no-install-recommends \
        chromium chromium-driver >/dev/null
fi

browser="$(find_browser)"
driver="$(find_driver)"
if [ -z "$browser" ] || [ -z "$driver" ]; then
    say "chromium or chromedriver still missing after the install"
    exit 1
fi

if [ -x "$VENV/bin/python" ] && ! "$VENV/bin/python" -c 'import selenium' 2>/dev/null; then
    say "installing selenium into $VENV"
    "$VENV/bin/python" -m pip install -q 'selenium>=4.10'
fi

echo "chromium=$browser"
echo "chromedriver=$driver"
