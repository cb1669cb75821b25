"""Our message types for bags: type names, the ``.msg`` schema directory and the rosbags typestore.

The ``.msg`` files in ``msg_schemas/msg`` are the single source of truth. rosbags parses them at
run time (no ROS build needed) and registers them next to the standard ROS 2 Jazzy types, so a
bag written with this typestore carries the same definitions and RIHS01 type hashes as one
recorded from an ``infinihand_msgs`` interface package built with rosidl.
"""

from collections.abc import Iterator
import logging
from pathlib import Path
import sys
from typing import Final

from infinihand_ros.core.errors import ConfigError
from rosbags.interfaces.typing import Typesdict
from rosbags.typesys import get_types_from_msg
from rosbags.typesys import get_typestore
from rosbags.typesys import Stores
from rosbags.typesys import TypesysError
from rosbags.typesys.store import Typestore

logger = logging.getLogger(__name__)

#: ROS package that installs the schemas (share/<package>/msg_schemas/msg).
PACKAGE_NAME: Final = 'infinihand_ros'
#: Interface-package namespace of our message types.
MSG_PACKAGE: Final = 'infinihand_msgs'
#: Schema directory relative to the source tree root and to the package share directory.
SCHEMA_SUBDIR: Final = Path('msg_schemas') / 'msg'
#: File suffix of message definitions.
MSG_SUFFIX: Final = '.msg'

MANO_PARAMETERS_MSG: Final = f'{MSG_PACKAGE}/msg/ManoParameters'
HAND_MSG: Final = f'{MSG_PACKAGE}/msg/Hand'
HAND_FRAME_MSG: Final = f'{MSG_PACKAGE}/msg/HandFrame'
KEYFRAME_POSES_MSG: Final = f'{MSG_PACKAGE}/msg/KeyframePoses'
#: Every type the schema directory must define.
OUR_MSG_TYPES: Final = (MANO_PARAMETERS_MSG, HAND_MSG, HAND_FRAME_MSG, KEYFRAME_POSES_MSG)

#: Standard types used by our bags and conversions (all part of the ROS 2 Jazzy typestore).
IMAGE_MSG: Final = 'sensor_msgs/msg/Image'
COMPRESSED_IMAGE_MSG: Final = 'sensor_msgs/msg/CompressedImage'
CAMERA_INFO_MSG: Final = 'sensor_msgs/msg/CameraInfo'
POSE_MSG: Final = 'geometry_msgs/msg/Pose'
POSE_STAMPED_MSG: Final = 'geometry_msgs/msg/PoseStamped'
POINT_MSG: Final = 'geometry_msgs/msg/Point'
QUATERNION_MSG: Final = 'geometry_msgs/msg/Quaternion'
HEADER_MSG: Final = 'std_msgs/msg/Header'
TIME_MSG: Final = 'builtin_interfaces/msg/Time'

#: Depth of ``infinihand_ros/bag/typestore.py`` below the source tree root.
_SOURCE_ROOT_PARENT_INDEX: Final = 2


def _installed_share_schema_dir() -> Path | None:
    """Return the schema directory under the ament index share dir, or None when unavailable."""
    try:
        from ament_index_python.packages import get_package_share_directory
        from ament_index_python.packages import PackageNotFoundError
    except ImportError:
        logger.debug('ament_index_python not importable; skipping the ament index lookup')
        return None
    try:
        return Path(get_package_share_directory(PACKAGE_NAME)) / SCHEMA_SUBDIR
    except (PackageNotFoundError, OSError) as exc:
        # OSError: AMENT_PREFIX_PATH unset or empty.
        logger.debug('%s not found through the ament index: %s', PACKAGE_NAME, exc)
        return None


def _candidate_schema_dirs() -> Iterator[Path]:
    """Yield the places the schema directory may be, most specific first."""
    # Source tree, or a colcon --symlink-install whose module files resolve into the source tree.
    yield Path(__file__).resolve().parents[_SOURCE_ROOT_PARENT_INDEX] / SCHEMA_SUBDIR
    installed = _installed_share_schema_dir()
    if installed is not None:
        yield installed
    # A plain `pip install .` puts setup.py's data_files under the environment prefix.
    yield Path(sys.prefix) / 'share' / PACKAGE_NAME / SCHEMA_SUBDIR


def msg_schema_dir() -> Path:
    """Find the directory that holds our ``.msg`` definitions.

    Looks in the source tree first (``<repo>/msg_schemas/msg``, also reached through a colcon
    symlink install), then in the installed share directory
    ``share/infinihand_ros/msg_schemas/msg`` found through ``ament_index_python`` (when importable
    and ``AMENT_PREFIX_PATH`` lists the install prefix), then under ``sys.prefix``.

    Returns:
        The first existing candidate directory.

    Raises:
        ConfigError: when no candidate exists, listing the places searched.

    """
    candidates = []
    for candidate in _candidate_schema_dirs():
        if candidate.is_dir():
            return candidate
        candidates.append(candidate)
    searched = ', '.join(str(path) for path in candidates)
    raise ConfigError(
        f'message schema directory {SCHEMA_SUBDIR} not found (searched: {searched}); run from '
        f'the source tree, or build with colcon and add the install prefix to AMENT_PREFIX_PATH')


def _resolve_schema_dir(schema_dir: Path | None) -> Path:
    """Return ``schema_dir`` (or the found schema directory) after checking it exists."""
    directory = msg_schema_dir() if schema_dir is None else Path(schema_dir)
    if not directory.is_dir():
        raise ConfigError(f'message schema directory {directory} does not exist; pass the '
                          f'directory that holds the infinihand_msgs .msg files')
    return directory


def our_message_definitions(schema_dir: Path | None = None) -> dict[str, str]:
    """Read the text of every ``.msg`` file of the schema directory.

    Args:
        schema_dir: directory of ``<TypeName>.msg`` files; ``msg_schema_dir()`` when None.

    Returns:
        Full type name (``infinihand_msgs/msg/<TypeName>``) -> ``.msg`` text, sorted by name.

    Raises:
        ConfigError: when the directory is missing or lacks one of ``OUR_MSG_TYPES``.

    """
    directory = _resolve_schema_dir(schema_dir)
    texts = {f'{MSG_PACKAGE}/msg/{path.stem}': path.read_text(encoding='utf-8')
             for path in sorted(directory.glob(f'*{MSG_SUFFIX}'))}
    missing = [name for name in OUR_MSG_TYPES if name not in texts]
    if missing:
        raise ConfigError(f'message schema directory {directory} lacks {missing}; expected one '
                          f'{MSG_SUFFIX} file per type in {list(OUR_MSG_TYPES)}')
    return texts


def our_message_types(schema_dir: Path | None = None) -> Typesdict:
    """Parse our ``.msg`` definitions into rosbags type definitions.

    Args:
        schema_dir: directory of ``<TypeName>.msg`` files; ``msg_schema_dir()`` when None.

    Returns:
        Full type name -> rosbags parse tree (constants, fields), ready for
        ``Typestore.register``.

    Raises:
        ConfigError: when the directory is missing, lacks one of ``OUR_MSG_TYPES`` or holds a
            definition rosbags cannot parse (the message names the type).

    """
    directory = _resolve_schema_dir(schema_dir)
    types: Typesdict = {}
    for typename, text in our_message_definitions(directory).items():
        try:
            types.update(get_types_from_msg(text, typename))
        except TypesysError as exc:
            path = directory / f'{typename.rsplit("/", 1)[-1]}{MSG_SUFFIX}'
            raise ConfigError(f'message definition {path} cannot be parsed as ROS 2 .msg: '
                              f'{exc}; fix the syntax of that file') from exc
    return types


def build_typestore(schema_dir: Path | None = None) -> Typestore:
    """Return a ROS 2 Jazzy typestore with our message types registered.

    Build it once and keep it: each call parses the schemas and generates code.

    Args:
        schema_dir: directory of our ``.msg`` files; ``msg_schema_dir()`` when None.

    Returns:
        A new ``Typestore`` holding the standard Jazzy types plus ``OUR_MSG_TYPES``.

    Raises:
        ConfigError: when a schema is missing or malformed, conflicts with a registered type, or
            refers to a type that neither the schemas nor ROS 2 Jazzy define.

    """
    types = our_message_types(schema_dir)
    typestore = get_typestore(Stores.ROS2_JAZZY)
    try:
        typestore.register(types)
    except TypesysError as exc:
        raise ConfigError(f'cannot register the infinihand_msgs types: {exc}') from exc
    for typename in types:
        try:
            typestore.hash_rihs01(typename)
        except KeyError as exc:
            raise ConfigError(
                f'message type {typename} refers to unknown type {exc.args[0]!r}; use a type '
                f'from ROS 2 Jazzy or add its .msg file to the schema directory') from exc
    return typestore
