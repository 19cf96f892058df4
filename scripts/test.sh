#!/usr/bin/env bash
# The test command: installs what is missing, then runs the whole suite (plunit for the
# Prolog platform, run from pytest, and pytest for everything else). Extra arguments go to
# pytest, e.g. `scripts/test.sh -m slow` for the long tests.
set -euo pipefail
. "$(dirname "${BASH_SOURCE[0]}")/setup.sh"
cd "$DFRL_ROOT"
# the cluster backend's engine and the TensorBoard writer (the optional extras "cluster" and
# "tensorboard", which the demo does not need), so that tests/cluster and the --tensorboard test run
# (and pytest-xdist, of the extra "dev": the suite runs on three workers, see README.md, Tests)
python -c 'import distributed, tensorboardX, xdist' 2>/dev/null \
    || python -m pip install -q -e "$DFRL_ROOT[dev,cluster,tensorboard,science]"
# the live view's browser test: Chromium and its driver from Debian's packages (if missing)
bash scripts/browser-setup.sh >/dev/null \
    || echo "[test] could not install chromium; the browser test will say why it skips" >&2
# Three workers (DFRL_TEST_WORKERS; 0 runs the suite in this process): the suite mostly waits,
# and a third worker fills the waits (README.md, Tests, has the times measured).
# Each worker takes whole test files (--dist loadfile: a file's module fixtures and its order
# stay together). The 25 slowest tests are listed at the end, so the suite's time stays in view,
# and the tests the marker expression left out (the slow ones) are named.
exec python -m pytest -q -n "${DFRL_TEST_WORKERS:-3}" --dist loadfile --durations=25 "$@"
