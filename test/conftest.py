"""Test-wide settings: markers, seeded generators and an isolated ROS 2 graph per process."""

import os

import numpy as np
import pytest

# Each pytest process gets its own DDS domain and stays on this machine, so parallel runs and CI
# never see each other's nodes. Set before anything imports rclpy.
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
os.environ.setdefault('ROS_DOMAIN_ID', str(1 + os.getpid() % 100))


def pytest_addoption(parser: pytest.Parser) -> None:
    """Add ``--ros-tests``: run the ROS tests too (``all``), only them, or all but them.

    ``make test`` runs the others on both cores first (``skip``, with pytest-xdist), then the
    ROS tests alone (``only``): live nodes and timed streams share the machine with nothing else
    of the suite's. It composes with ``-m`` and ``-k``.
    """
    parser.addoption('--ros-tests', choices=('all', 'skip', 'only'), default='all',
                     help='run the tests marked ros too (all), only them, or all but them')


def pytest_configure(config: pytest.Config) -> None:
    """Register the project's markers."""
    config.addinivalue_line(
        'markers', 'ros: needs rclpy and a ROS 2 environment, or a live node (runs alone)')
    config.addinivalue_line(
        'markers', 'slow: end-to-end test (runs in CI; skip with -m "not slow")')
    config.addinivalue_line('markers', 'linter: code style check')


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Deselect the tests ``--ros-tests`` leaves out; run the long ones of the rest first."""
    choice = config.getoption('--ros-tests')
    if choice == 'all':
        return
    keep, deselected = [], []
    for item in items:
        wanted = (item.get_closest_marker('ros') is not None) == (choice == 'only')
        (keep if wanted else deselected).append(item)
    if deselected:
        config.hook.pytest_deselected(items=deselected)
    # The end-to-end tests first: the parallel pass then ends on short tests on both cores.
    items[:] = sorted(keep, key=lambda item: not (item.get_closest_marker('slow')
                                                  or item.get_closest_marker('linter')))


@pytest.fixture
def rng() -> np.random.Generator:
    """Return a seeded random generator (the same sequence in every test)."""
    return np.random.default_rng(12345)
