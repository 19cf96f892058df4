"""``python -m dfrl``: the ``dfrl`` command line."""

import sys

from dfrl.experiments.cli import main

sys.exit(main())
