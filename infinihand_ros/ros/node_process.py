"""The process around one of our nodes: init, spin until SIGINT/SIGTERM, clean shutdown.

SIGINT and SIGTERM (rclpy's signal handlers) end the spin; the node's ``close()`` stops its
threads; the process exits 0. Before spinning, what start-up made is frozen out of the garbage
collector (``gc.freeze``), so its full collections stall the node's threads far less. A node whose
construction raises ``InfiniHandError`` (a bad parameter, config or checkpoint) logs one error line
naming it and the process exits 1.

Our commands use the package's Fast DDS profile unless the user chose a profile file
(``use_package_dds_profile``, called before ``rclpy.init``). The profile
(``config/fastdds_profile.xml``) gives Fast DDS a 16 MB shared-memory segment, so best-effort
raw images cross processes without loss (the default segment is smaller than one 518x378
frame). Fast DDS 2.x (ROS 2 Jazzy) reads ``FASTRTPS_DEFAULT_PROFILES_FILE`` when the first
participant is created. A profile file the user set (in that variable or in Fast DDS 3's
``FASTDDS_DEFAULT_PROFILES_FILE``), or another RMW than Fast DDS, is left alone.
"""

import argparse
from collections.abc import Callable
from collections.abc import MutableMapping
import gc
import os
from pathlib import Path
import sys
from typing import Final

from infinihand_ros.core.config import config_dir
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.core.parameters import parameters_help
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.executors import SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.node import Node
from rclpy.utilities import remove_ros_args
PROFILE_FILE: Final = 'fastdds_profile.xml'
PROFILE_VARIABLES: Final = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE')
RMW_VARIABLE: Final = 'RMW_IMPLEMENTATION'
FAST_DDS_RMW_PREFIX: Final = 'rmw_fastrtps'


def use_package_dds_profile(environ: MutableMapping[str, str] | None = None) -> Path | None:
    """Point Fast DDS at the package's profile unless the user set one; return it if set.

    Args:
        environ: the environment to change (default: this process's ``os.environ``, which
            the RMW reads when rclpy creates the first participant).

    """
    environ = os.environ if environ is None else environ
    if any(environ.get(name) for name in PROFILE_VARIABLES):
        return None
    if not environ.get(RMW_VARIABLE, FAST_DDS_RMW_PREFIX).startswith(FAST_DDS_RMW_PREFIX):
        return None
    profile = config_dir() / PROFILE_FILE
    if not profile.is_file():
        return None
    environ[PROFILE_VARIABLES[0]] = str(profile)
    return profile


EXIT_OK: Final = 0
EXIT_BAD_START: Final = 1


def parse_command_line(name: str, description: str, config_type: type,
                       args: list[str] | None = None) -> None:
    """Handle the non-ROS arguments: ``-h``/``--help`` prints the node and its parameters.

    ROS arguments (``--ros-args ...``) are left to rclpy; any other argument is refused with a
    usage message (exit 2).
    """
    argv = remove_ros_args(args=sys.argv if args is None else args)[1:]
    parser = argparse.ArgumentParser(
        prog=name, description=description, formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog='Parameters (set with --ros-args -p NAME:=VALUE or --params-file FILE):\n'
               + parameters_help(config_type))
    parser.parse_args(argv)


#: rclpy's error for a wait set made on a context a signal has just shut down (SIGINT mid-spin).
RCLError: Final = rclpy_implementation.RCLError


def shut_down_by_signal(exc: BaseException) -> bool:
    """Return whether ``exc`` only says that the context was shut down while spinning."""
    return isinstance(exc, (KeyboardInterrupt, ExternalShutdownException)) or (
        isinstance(exc, RCLError) and not rclpy.ok())


def run_node(make_node: Callable[[], Node], name: str, args: list[str] | None = None) -> int:
    """Create the node with ``make_node`` and spin it until shut down; return the exit code.

    The node must have a ``close()`` that stops its threads (both of our nodes do).
    """
    use_package_dds_profile()
    rclpy.init(args=args)
    try:
        node = make_node()
    except InfiniHandError as exc:
        rclpy.logging.get_logger(name).error(f'cannot start: {exc}')
        rclpy.try_shutdown()
        return EXIT_BAD_START
    except (KeyboardInterrupt, RCLError) as exc:  # SIGINT or SIGTERM during start-up
        if not shut_down_by_signal(exc):
            raise
        rclpy.try_shutdown()
        return EXIT_OK
    # What start-up made (the model, rclpy, MediaPipe) leaves the collector's generations, so a
    # full collection scans only what the stream makes: it stalls every thread for ~25 ms
    # instead of ~170 ms (the estimator on a 2-core CPU), a few times a minute.
    gc.collect()
    gc.freeze()
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException, RCLError) as exc:
        if not shut_down_by_signal(exc):
            raise
    finally:
        node.close()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return EXIT_OK
