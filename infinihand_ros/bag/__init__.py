"""Bag I/O without ROS: our message types, conversions, readers and writers (rosbags)."""
