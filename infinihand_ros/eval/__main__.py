"""``python -m infinihand_ros.eval``: see ``eval/cli.py``."""

import sys

from infinihand_ros.eval.cli import main

sys.exit(main())
