"""Test-wide settings: markers, seeded generators and an isolated ROS 2 graph per process."""

import os

import numpy as np
import pytest

# Each pytest process gets its own DDS domain and stays on this machine, so parallel runs and CI
# never see each other's nodes. Set before anything imports rclpy.
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))


def pytest_configure(config: pytest.Config) -> None:
    """Register the project's markers."""
    config.addinivalue_line('markers', 'ros: needs rclpy and a ROS 2 environment')
    config.addinivalue_line(
        'markers', 'slow: end-to-end test (runs in CI; skip with -m "not slow")')
    config.addinivalue_line('markers', 'linter: code style check')


@pytest.fixture
def rng() -> np.random.Generator:
    """Return a seeded random generator (the same sequence in every test)."""
    return np.random.default_rng(12345)
