"""Synthetic egocentric sequences with exact ground truth: scenes, camera motion, rendering."""
