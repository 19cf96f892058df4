#!/usr/bin/env bash
# The test command: installs what is missing, then runs the whole suite (plunit for the
# Prolog platform, run from pytest, and pytest for everything else). Extra arguments go to
# pytest, e.g. `scripts/test.sh -m slow` for the long tests.
set -euo pipefail
. "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
cd "$DFRL_ROOT"
exec python -m pytest -q "$@"
