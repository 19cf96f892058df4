"""``python -m dfrl.experiments.robot_host --config NODE.json``."""

import sys

from dfrl.experiments.robot_host.process import main

sys.exit(main())
