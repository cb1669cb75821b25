"""``python -m infinihand_ros.train`` (also what ``torchrun -m`` launches): see ``cli.py``."""

import sys

from infinihand_ros.train.cli import main

sys.exit(main())
