"""Tests of infinihand_ros/bag/typestore.py: schema lookup, parsing, registration, type hashes.

The golden RIHS01 hashes in ``rihs01_hashes.json`` pin the wire identity of our message types: a
bag or a live topic only matches when the hash of its type agrees. Any edit of a field (name,
type, order, array size) in ``msg_schemas/msg`` changes the hash and fails
``test_our_type_hashes_match_golden`` on purpose. When such a change is deliberate, regenerate
the file with ``python test/bag/test_typestore.py`` (from the repository root, with the package
importable, e.g. after ``source scripts/env.sh``) and commit it with the .msg change; old bags
then need their types read from the definitions stored in them. Comments do not change hashes.
"""

import json
from pathlib import Path
import re
import sys

from infinihand_ros.bag import typestore as typestore_module
from infinihand_ros.bag.typestore import build_typestore
from infinihand_ros.bag.typestore import HAND_FRAME_MSG
from infinihand_ros.bag.typestore import HAND_MSG
from infinihand_ros.bag.typestore import IMAGE_MSG
from infinihand_ros.bag.typestore import MANO_PARAMETERS_MSG
from infinihand_ros.bag.typestore import msg_schema_dir
from infinihand_ros.bag.typestore import our_message_definitions
from infinihand_ros.bag.typestore import our_message_types
from infinihand_ros.bag.typestore import OUR_MSG_TYPES
from infinihand_ros.bag.typestore import PACKAGE_NAME
from infinihand_ros.bag.typestore import SCHEMA_SUBDIR
from infinihand_ros.core.errors import ConfigError
import pytest
from rosbags.typesys.store import Typestore

GOLDEN_PATH = Path(__file__).with_name('rihs01_hashes.json')
RIHS01_PATTERN = re.compile(r'^RIHS01_[0-9a-f]{64}$')
#: Standard types whose hashes we compare with the JSON type descriptions of the ROS wheels.
STANDARD_TYPES = ('sensor_msgs/msg/Image', 'sensor_msgs/msg/CameraInfo',
                  'geometry_msgs/msg/PoseStamped', 'std_msgs/msg/Header')


def _copy_schemas(target: Path, strip_comments: bool = False) -> Path:
    """Copy our .msg files into ``target`` (optionally without comments); return ``target``."""
    target.mkdir(parents=True, exist_ok=True)
    for typename, text in our_message_definitions().items():
        if strip_comments:
            text = '\n'.join(line.split('#', 1)[0].rstrip() for line in text.splitlines())
        (target / f'{typename.rsplit("/", 1)[-1]}.msg').write_text(text)
    return target


def _our_hashes(store: Typestore) -> dict[str, str]:
    """Return the RIHS01 hash of each of our types."""
    return {typename: store.hash_rihs01(typename) for typename in OUR_MSG_TYPES}


def test_schema_dir_is_found_in_the_source_tree() -> None:
    found = msg_schema_dir()
    assert found.parts[-2:] == SCHEMA_SUBDIR.parts
    assert {f'infinihand_msgs/msg/{path.stem}' for path in found.glob('*.msg')} == set(
        OUR_MSG_TYPES)


def test_schema_dir_missing_everywhere_names_the_places_searched(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    nowhere = tmp_path / 'nowhere'
    monkeypatch.setattr(typestore_module, '_candidate_schema_dirs', lambda: iter([nowhere]))
    with pytest.raises(ConfigError, match=f'not found \\(searched: {re.escape(str(nowhere))}'):
        msg_schema_dir()


def test_installed_share_dir_is_found_through_the_ament_index(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    pytest.importorskip('ament_index_python')
    prefix = tmp_path / 'install'
    marker = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / PACKAGE_NAME
    marker.parent.mkdir(parents=True)
    marker.touch()
    share_schemas = _copy_schemas(prefix / 'share' / PACKAGE_NAME / SCHEMA_SUBDIR)
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(prefix))
    assert typestore_module._installed_share_schema_dir() == share_schemas
    monkeypatch.delenv('AMENT_PREFIX_PATH')
    assert typestore_module._installed_share_schema_dir() is None


def test_definitions_and_parse_trees_cover_our_types() -> None:
    texts = our_message_definitions()
    assert list(texts) == sorted(OUR_MSG_TYPES)
    assert 'geometry_msgs/Point[21] joints_camera' in texts[HAND_MSG]
    types = our_message_types()
    constants, fields = types[HAND_MSG]
    assert [name for name, _, _ in constants] == ['LEFT', 'RIGHT']
    assert [name for name, _ in fields][:3] == ['side', 'confidence', 'mano_camera']


def test_build_typestore_adds_our_types_to_jazzy(typestore: Typestore) -> None:
    for typename in OUR_MSG_TYPES:
        assert typename in typestore.types
    assert IMAGE_MSG in typestore.types
    hand_class = typestore.types[HAND_MSG]
    assert (hand_class.LEFT, hand_class.RIGHT) == (0, 1)
    # A second store is independent: registering never leaks into rosbags' shared stores.
    assert HAND_FRAME_MSG in build_typestore().types


def test_our_type_hashes_match_golden(typestore: Typestore) -> None:
    golden = json.loads(GOLDEN_PATH.read_text())
    hashes = _our_hashes(typestore)
    assert all(RIHS01_PATTERN.match(value) for value in hashes.values())
    assert hashes == golden, (
        'an infinihand_msgs type changed its wire identity; if deliberate, regenerate '
        f'{GOLDEN_PATH.name} with `python test/bag/test_typestore.py`')


def test_hashes_ignore_comments_but_not_fields(tmp_path: Path, typestore: Typestore) -> None:
    stripped = build_typestore(_copy_schemas(tmp_path / 'stripped', strip_comments=True))
    assert _our_hashes(stripped) == _our_hashes(typestore)
    changed_dir = _copy_schemas(tmp_path / 'changed')
    mano_path = changed_dir / 'ManoParameters.msg'
    mano_path.write_text(mano_path.read_text().replace('float64[10] betas', 'float64[16] betas'))
    changed = _our_hashes(build_typestore(changed_dir))
    original = _our_hashes(typestore)
    # ManoParameters changed, and so did every type that nests it; KeyframePoses does not.
    nesting = {MANO_PARAMETERS_MSG, HAND_MSG, HAND_FRAME_MSG}
    assert {name for name in OUR_MSG_TYPES if changed[name] != original[name]} == nesting


def _ros_share_dir() -> Path:
    """Return the share directory of the installed ROS wheels (ament index, else sys.prefix)."""
    packages = pytest.importorskip('ament_index_python.packages')
    try:
        return Path(packages.get_package_share_directory('sensor_msgs')).parent
    except (packages.PackageNotFoundError, OSError):  # OSError: AMENT_PREFIX_PATH unset
        return Path(sys.prefix) / 'share'


@pytest.mark.ros
@pytest.mark.parametrize('typename', STANDARD_TYPES)
def test_standard_type_hashes_match_ros_jazzy(typestore: Typestore, typename: str) -> None:
    pytest.importorskip('sensor_msgs.msg')
    package, _, name = typename.split('/')
    description = _ros_share_dir() / package / 'msg' / f'{name}.json'
    if not description.is_file():
        pytest.skip(f'no rosidl type description at {description}')
    hashes = json.loads(description.read_text())['type_hashes']
    ros_hash = next(item['hash_string'] for item in hashes if item['type_name'] == typename)
    assert typestore.hash_rihs01(typename) == ros_hash


@pytest.mark.ros
@pytest.mark.filterwarnings('ignore:module .sre_:DeprecationWarning')
def test_our_hashes_match_the_rosidl_toolchain(tmp_path: Path, typestore: Typestore) -> None:
    """Run rosidl's own .msg -> .idl -> type-hash pipeline (from the wheels) on our schemas."""
    msg_adapter = pytest.importorskip('rosidl_adapter.msg')
    type_description = pytest.importorskip('rosidl_generator_type_description')
    schema_root = msg_schema_dir().parent
    idl_root = tmp_path / 'idl'
    (idl_root / 'msg').mkdir(parents=True)
    idl_tuples = []
    for msg_path in sorted(msg_schema_dir().glob('*.msg')):
        idl_path = msg_adapter.convert_msg_to_idl(
            schema_root, 'infinihand_msgs', Path('msg') / msg_path.name, idl_root / 'msg')
        idl_tuples.append(f'{idl_root}:msg/{idl_path.name}')
    share = _ros_share_dir()
    arguments = {
        'package_name': 'infinihand_msgs', 'output_dir': str(tmp_path / 'generated'),
        'idl_tuples': idl_tuples,
        'include_paths': [f'{package}:{share / package}'
                          for package in ('builtin_interfaces', 'geometry_msgs', 'std_msgs')]}
    arguments_path = tmp_path / 'arguments.json'
    arguments_path.write_text(json.dumps(arguments))
    rosidl_hashes = {}
    for path in type_description.generate_type_hash(str(arguments_path)):
        top = json.loads(path.read_text())['type_hashes'][0]
        rosidl_hashes[top['type_name']] = top['hash_string']
    assert rosidl_hashes == _our_hashes(typestore)


def test_missing_schema_dir_raises(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match='schema directory .*missing.* does not exist'):
        build_typestore(tmp_path / 'missing')


def test_schema_dir_without_a_type_raises(tmp_path: Path) -> None:
    schema_dir = _copy_schemas(tmp_path / 'msg')
    (schema_dir / 'Hand.msg').unlink()
    with pytest.raises(ConfigError, match=r"lacks \['infinihand_msgs/msg/Hand'\]"):
        our_message_types(schema_dir)


def test_malformed_msg_raises_naming_the_file(tmp_path: Path) -> None:
    schema_dir = _copy_schemas(tmp_path / 'msg')
    (schema_dir / 'HandFrame.msg').write_text('float64[9 k\n')
    with pytest.raises(ConfigError, match='HandFrame.msg cannot be parsed as ROS 2 .msg'):
        build_typestore(schema_dir)


def test_unknown_nested_type_raises(tmp_path: Path) -> None:
    schema_dir = _copy_schemas(tmp_path / 'msg')
    (schema_dir / 'KeyframePoses.msg').write_text('geometry_msgs/NoSuchType pose\n')
    with pytest.raises(ConfigError, match="refers to unknown type 'geometry_msgs/msg/NoSuchType'"):
        build_typestore(schema_dir)


def _write_golden() -> None:
    """Regenerate the golden hashes from the current .msg files (a deliberate act)."""
    hashes = _our_hashes(build_typestore())
    GOLDEN_PATH.write_text(json.dumps(hashes, indent=2, sort_keys=True) + '\n')


if __name__ == '__main__':
    _write_golden()
