"""Our commands use the package's Fast DDS profile unless the user chose a profile file.

The profile (``config/fastdds_profile.xml``) gives Fast DDS a 16 MB shared-memory segment, so
best-effort raw images cross processes without loss (the default segment is smaller than one
518x378 frame). Fast DDS 2.x (ROS 2 Jazzy) reads ``FASTRTPS_DEFAULT_PROFILES_FILE`` when the
first participant is created, so each entry point calls ``use_package_dds_profile`` before
``rclpy.init``. A profile file the user set (in that variable or in Fast DDS 3's
``FASTDDS_DEFAULT_PROFILES_FILE``), or another RMW than Fast DDS, is left alone.
"""

from collections.abc import MutableMapping
import os
from pathlib import Path
from typing import Final

from infinihand_ros.core.config import config_dir

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
