#!/usr/bin/env bash
# The test command: installs what is missing, then runs the whole suite (plunit for the
# Prolog platform, run from pytest, and pytest for everything else). Extra arguments go to
# pytest, e.g. `scripts/test.sh -m slow` for the long tests.
set -euo pipefail
. "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
cd "$DFRL_ROOT"
# the cluster backend's engine and the TensorBoard writer (the optional extras "cluster" and
# "tensorboard", which the demo does not need), so that tests/cluster and the --tensorboard test run
python -c 'import distributed, tensorboardX' 2>/dev/null \
    || python -m pip install -q -e "$DFRL_ROOT[dev,cluster,tensorboard]"
# the live view's browser test: Chromium and its driver from Debian's packages (if missing)
bash scripts/browser-setup.sh >/dev/null \
    || echo "[test] could not install chromium; the browser test will say why it skips" >&2
# the 25 slowest tests are listed at the end, so the suite's time can be kept in view
exec python -m pytest -q --durations=25 "$@"
