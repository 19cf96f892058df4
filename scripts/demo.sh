#!/usr/bin/env bash
# The main job: installs what is missing, then runs the 5-robot dFRL demo on loopback and
# leaves its plots and summary in results/. Extra arguments go to `dfrl demo`.
set -euo pipefail
. "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
cd "$DFRL_ROOT"
exec dfrl demo "$@"
