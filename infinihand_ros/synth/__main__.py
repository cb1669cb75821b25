"""``python -m infinihand_ros.synth``: generate a synthetic sequence (see ``synth/cli.py``)."""

import sys

from infinihand_ros.synth.cli import main

sys.exit(main())
