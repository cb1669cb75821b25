"""Image sequences and GIFs into a dataset, on a real egocentric clip (skipped when absent).

The EPIC-KITCHENS frames of ``../shared/data/real_ego/epic_p01_01`` (11 JPEGs at about 10 Hz)
as the folder EPIC ships, and the same frames as an animated GIF.
"""

import json
from pathlib import Path
import shutil

from convert_builders import fast_config
from infinihand_ros.convert.cli import EXIT_OK
from infinihand_ros.convert.cli import EXIT_USAGE
from infinihand_ros.convert.cli import main
from infinihand_ros.convert.cli import REPORT_FILE
from infinihand_ros.convert.image_frames import UNREADABLE
from infinihand_ros.convert.lerobot_features import INTRINSICS
from PIL import Image
import pyarrow.parquet as pq
import pytest

CLIP = Path(__file__).resolve().parents[3] / 'shared' / 'data' / 'real_ego' / 'epic_p01_01'
DATA = 'data/chunk-000/file-{:03d}.parquet'

pytestmark = pytest.mark.slow


@pytest.fixture(scope='module')
def jpegs() -> list[Path]:
    """Return the clip's frames (skips when the shared data is absent)."""
    frames = sorted((CLIP / 'frames').glob('*.jpg'))
    if not frames:
        pytest.skip(f'no real clip at {CLIP} (shared data absent)')
    return frames


def _convert(inputs: list[Path], output: Path, tmp_path: Path, *flags: str) -> int:
    return main([*map(str, inputs), '--output', str(output), '--quiet', '--no-estimates-bag',
                 '--config', str(fast_config(tmp_path / 'convert.yaml')), *flags])


def test_a_folder_of_frames_is_one_episode(jpegs: list[Path], tmp_path: Path,
                                           capsys: pytest.CaptureFixture) -> None:
    """Sorted by name at --input-fps; a broken file is skipped and counted; no rate: refused."""
    folder = tmp_path / 'P01_01'
    folder.mkdir()
    for index, frame in enumerate(jpegs):
        shutil.copy(frame, folder / f'frame_{index + 1:010d}.jpg')
    (folder / 'frame_0000000099.jpg').write_bytes(b'not a jpeg')
    output = tmp_path / 'dataset'
    assert _convert([folder], output, tmp_path) == EXIT_USAGE
    assert 'pass the rate they were taken at with --input-fps' in capsys.readouterr().err
    assert _convert([folder], output, tmp_path, '--input-fps', '10') == EXIT_OK
    info = json.loads((output / 'meta/info.json').read_text())
    assert info['total_episodes'] == 1 and info['total_frames'] == len(jpegs)
    assert info['features']['observation.images.ego']['shape'] == [256, 456, 3]
    report = json.loads((output / REPORT_FILE).read_text())
    assert report[0]['skipped'] == {UNREADABLE: 1}
    data = pq.read_table(output / DATA.format(0)).to_pydict()
    assert len({tuple(row) for row in data[INTRINSICS]}) == 1  # one lens for the episode


def test_an_animated_gif_is_a_video(jpegs: list[Path], tmp_path: Path) -> None:
    """Its frame times are the GIF's own (100 ms here): 11 frames, 1.1 s at 10 Hz."""
    gif = tmp_path / 'clip.gif'
    images = [Image.open(frame) for frame in jpegs]
    images[0].save(gif, save_all=True, append_images=images[1:], duration=100, loop=0)
    output = tmp_path / 'dataset'
    assert _convert([gif], output, tmp_path) == EXIT_OK
    info = json.loads((output / 'meta/info.json').read_text())
    assert info['total_episodes'] == 1 and info['total_frames'] == len(jpegs)
