"""``python -m dfrl.experiments.robot_node --config NODE.json``."""
import sys

from dfrl.experiments.robot_node.process import main

sys.exit(main())
