"""The dataset card: ``README.md`` at the dataset root, in the Hugging Face dataset-card form.

A YAML header (licence left for the user, task categories, tags, the data files) and then what
a user needs before training on the data: the features with their names and units, the frames
and conventions, how the episodes were made (inputs, image fitting, provenance) and the
limitations of the model that made them (its own card's section when it has one). The card is
a function of the metadata only, so a resumed run writes the same card as an uninterrupted one.
"""

from collections import Counter
import json
from pathlib import Path
from typing import Any, Final

from infinihand_ros.convert import lerobot_features as feat
from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.engine.hands.config import MEDIAPIPE
from infinihand_ros.model.io.bundled import resolve_checkpoint

CARD_FILE: Final = 'README.md'
LIMITATIONS_HEADING: Final = '## Limitations'

#: feature key -> (units, what it holds).
FEATURE_NOTES: Final = {
    feat.STATE: ('m; 6D rotation unitless', 'per hand: wrist position, wrist rotation as 6D '
                 '(first two columns of the MANO global orientation), 5 fingertips; left '
                 'then right'),
    feat.ACTION: ('as observation.state', 'observation.state of a later frame '
                  '(convert.dataset.action_offset)'),
    feat.CAMERA_POSE: ('m', 'camera-to-world pose T_world_cam, row-major 4x4, on the final '
                       'trajectory of the episode'),
    feat.INTRINSICS: ('px', 'fx, fy, cx, cy of the video frame (pixel centres at integers); '
                      "the lens distortion is the episode's `lens` in meta/conversion.json"),
    feat.CAMERA_FLAGS: ('bool', 'keyframe (entered the streaming memory); ba_corrected '
                        '(bundle adjustment moved the pose); tracked (the pose was measured in '
                        "the image, else the network's motion was used); reinitialised (the "
                        'camera track restarted here: a discontinuity such as a cut); '
                        'ba_failed (the last bundle-adjustment call over this keyframe failed: '
                        'the solver raised or its process died, so the pose lacks that '
                        'refinement); episode_refined (the pose carries the bundle adjustment '
                        'of the whole episode, used where it explained held-out feature tracks '
                        "better than the stream's poses; the report says why when it was not)"),
    feat.HAND_VALID: ('bool', 'the hand was detected and placed in the world; the other hand '
                      'features of an invalid hand hold the fill value'),
    feat.HAND_CONFIDENCE: ('[0, 1]', "the hand source's presence score (kept for invalid "
                           'hands)'),
    feat.WRIST_POSE: ('m; quaternion xyzw', 'wrist position and orientation in the world'),
    feat.KEYPOINTS_WORLD: ('m', '21 joints per hand in the world, OpenPose/MediaPipe order'),
    feat.KEYPOINTS_WRIST: ('m', "21 joints per hand in the hand's wrist frame "
                           '(dex-retargeting convention)'),
    feat.MANO_GLOBAL_ORIENT: ('rad (axis-angle)', 'MANO global orientation in the world'),
    feat.MANO_HAND_POSE: ('rad (axis-angle)', '15 MANO joint rotations relative to the flat '
                          'hand'),
    feat.MANO_BETAS: ('unitless', 'hand shape coefficients'),
    feat.SOURCE_STAMP: ('ns', 'stamp of the source image this frame was taken from'),
    feat.TIMESTAMP: ('s', 'frame_index / fps, from the episode start'),
}

CONVENTIONS: Final = """\
- Units: metres, radians, seconds; images RGB.
- World frame: the first frame's camera of each episode (OpenCV optical: x right, y down,
  z forward); poses are camera-to-world.
- Hands: left, then right in every per-hand feature; 21 joints in OpenPose/MediaPipe order
  (0 wrist, 1-4 thumb, 5-8 index, 9-12 middle, 13-16 ring, 17-20 pinky); the per-dimension
  names in `meta/info.json` spell the order out.
- Timestamps: `frame_index / fps` exactly; each input is resampled to the dataset's rate
  (nearest source frame; `source.stamp_ns` says which).
- Inputs of another image size were scaled and letterboxed or cropped to the dataset's video
  size before estimation; each episode's mapping (`dataset px = scale * source px + offset`)
  and original size are in `meta/infinihand_conversion.json`."""


def _header(info: dict[str, Any]) -> str:
    return '\n'.join([
        '---',
        '# license: set the licence of your recordings here (e.g. cc-by-4.0)',
        'license: null',
        'task_categories:',
        '- robotics',
        'tags:',
        '- LeRobot',
        '- hands',
        '- hand-pose-estimation',
        '- egocentric',
        '- infinihand_ros',
        f"- {info['robot_type']}",
        'configs:',
        '- config_name: default',
        '  data_files: data/*/*.parquet',
        '---'])


def _features(info: dict[str, Any]) -> list[str]:
    lines = ['| feature | dtype | shape | units | what it holds |', '|---|---|---|---|---|']
    for key, spec in info['features'].items():
        if spec['dtype'] == 'video':
            units, what = 'RGB uint8', f"ego camera video, {spec['shape'][1]}x{spec['shape'][0]}"
        else:
            units, what = FEATURE_NOTES.get(key, ('', 'LeRobot index'))
        lines.append(f"| `{key}` | {spec['dtype']} | {spec['shape']} | {units} | {what} |")
    return lines


def _made(records: list[dict[str, Any]]) -> list[str]:
    provenances = Counter(json.dumps(record.get('provenance', {}), sort_keys=True)
                          for record in records)
    lines = ['Converted by `bag_to_dataset` (infinihand_ros) from these inputs:', '',
             '| episode | source | original size | fitting | lens distortion |',
             '|---|---|---|---|---|']
    for record in records:
        image = record.get('image') or {}
        size = 'x'.join(map(str, image.get('source_size', []))) or 'unknown'
        lines.append(f"| {record['episode_index']} | `{record['source']}` | {size} | "
                     f"{image.get('mode', 'unknown')} | {_lens_text(record.get('lens'))} |")
    lines += ['', 'Provenance (episodes: what made them):', '']
    for text, count in provenances.items():
        lines.append(f'- {count} episode(s): `{text}`')
    return lines


def _lens_text(lens: dict[str, Any] | None) -> str:
    """Return an episode's lens as the card shows it (``meta/conversion.json`` has it all)."""
    if not lens or lens.get('distortion_model') is None:
        return 'none (pinhole)'
    coefficients = ', '.join(f'{value:g}' for value in lens.get('distortion', []))
    return f"{lens['distortion_model']}: {coefficients}"


def _limitations(records: list[dict[str, Any]]) -> list[str]:
    """Return the Limitations section of each model card the episodes' weights came with."""
    names = sorted({weights['name'] for record in records
                    for weights in record.get('provenance', {}).get('weights', {}).values()
                    if 'name' in weights})
    lines = ['Estimates are model outputs, not measurements: check `hands.valid`, '
             '`hands.confidence` and the per-episode reports before training on them.']
    if any(record.get('provenance', {}).get('hand_source') == MEDIAPIPE for record in records):
        lines += ['', 'Episodes whose hands come from MediaPipe (`hand_source: mediapipe`): '
                  "`hands.mano.betas` is the hand model's mean shape (zeros) unless the "
                  "engine's `hands.refine_iterations` fitted the shape, and each hand's "
                  'distance from the camera follows from its size in pixels and the '
                  'intrinsics.']
    for name in names:
        try:
            card = (Path(resolve_checkpoint(name)) / CARD_FILE).read_text(encoding='utf-8')
        except (OSError, InfiniHandError):
            continue
        if LIMITATIONS_HEADING in card:
            section = card.split(LIMITATIONS_HEADING, 1)[1].split('\n## ', 1)[0].strip()
            lines += ['', f'From the card of the model `{name}`:', '', section]
    return lines


def dataset_card(info: dict[str, Any], records: list[dict[str, Any]],
                 tasks: list[str]) -> str:
    """Return the card of a dataset with ``info.json`` ``info`` and episode ``records``."""
    parts = [
        _header(info), '', '# Hand demonstrations (LeRobot v3.0)', '',
        f"{info['total_episodes']} episodes, {info['total_frames']} frames at {info['fps']} "
        f"fps, robot type `{info['robot_type']}`; tasks: "
        + ', '.join(f'`{task}`' for task in tasks) + '.', '',
        '## Features', '', *_features(info), '',
        '## Frames and conventions', '', CONVENTIONS, '',
        '## How it was made', '', *_made(records), '',
        '## Limitations', '', *_limitations(records), '']
    return '\n'.join(parts)
