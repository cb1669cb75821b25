"""InfiniHand for ROS 2: streaming world-space 3D hands and camera trajectories from video."""

__version__ = '0.1.0'
