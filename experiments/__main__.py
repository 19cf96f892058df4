"""``python -m experiments`` runs the ``dfrl`` command line."""
import sys

from experiments.cli import main

sys.exit(main())
