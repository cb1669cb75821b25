"""Bags and videos to LeRobot v3.0 datasets of hand demonstrations (``bag_to_dataset``)."""
