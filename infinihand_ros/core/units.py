"""Unit constants shared by every package (stamps are integer nanoseconds)."""

from typing import Final

#: Nanoseconds per second (an int: stamps stay exact; divide for seconds as floats).
NS_PER_S: Final = 1_000_000_000
