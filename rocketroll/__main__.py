"""``python -m rocketroll``: the ``rocketroll`` command line."""

import sys

from rocketroll.cli import main

sys.exit(main())
