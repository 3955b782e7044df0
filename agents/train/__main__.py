"""``python -m agents.train``: ``rocketroll train ppo``."""

import sys

from agents.cli import TRAIN_COMMAND
from rocketroll_common.settings import run_command

sys.exit(run_command(TRAIN_COMMAND, sys.argv[1:], "python -m agents.train"))
