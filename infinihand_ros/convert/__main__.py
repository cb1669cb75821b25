"""``python -m infinihand_ros.convert``: the same as ``bag_to_dataset``."""

from infinihand_ros.convert.cli import console_main

console_main()
