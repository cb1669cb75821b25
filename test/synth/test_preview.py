"""Preview drawings: skeleton overlay and contact sheet."""

from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.synth.preview import contact_sheet
from infinihand_ros.synth.preview import draw_skeleton
from infinihand_ros.synth.preview import LABEL_BAR_PX
import numpy as np
import pytest


def _joints() -> np.ndarray:
    angles = np.linspace(0.0, np.pi, NUM_JOINTS)
    return np.stack([50 + 30 * np.cos(angles), 50 - 30 * np.sin(angles)], axis=1)


def test_draw_skeleton_marks_joints_and_keeps_the_input() -> None:
    image = np.zeros((100, 120, 3), np.uint8)
    joints = _joints()
    out = draw_skeleton(image, joints, RIGHT)
    assert out.shape == image.shape and out.dtype == np.uint8
    assert not image.any()  # the input is not modified
    for u, v in np.round(joints).astype(int):
        assert out[v, u].any()
    assert np.any(draw_skeleton(image, joints, LEFT) != out)  # sides are tinted differently


def test_draw_skeleton_skips_non_finite_joints() -> None:
    joints = _joints()
    joints[5:] = np.nan
    out = draw_skeleton(np.zeros((100, 120, 3), np.uint8), joints, LEFT)
    u, v = np.round(_joints()[12]).astype(int)
    assert not out[v, u].any()
    assert out[int(round(joints[2, 1])), int(round(joints[2, 0]))].any()


def test_draw_skeleton_rejects_bad_input() -> None:
    with pytest.raises(InputError, match='joints_2d: expected shape'):
        draw_skeleton(np.zeros((10, 10, 3), np.uint8), np.zeros((20, 2)), LEFT)
    with pytest.raises(ValueError, match='hand side'):
        draw_skeleton(np.zeros((10, 10, 3), np.uint8), _joints(), 3)


def test_contact_sheet_tiles_images_with_labels() -> None:
    images = [np.full((40, 60, 3), 50 * (i + 1), np.uint8) for i in range(5)]
    sheet = contact_sheet(images, cols=3, labels=[f'#{i}' for i in range(5)])
    tile_h = 40 + LABEL_BAR_PX
    assert sheet.shape == (2 * tile_h, 180, 3)
    below = tile_h + LABEL_BAR_PX + 5
    np.testing.assert_array_equal(sheet[below, 5], [200, 200, 200])  # image 3: row 1, col 0
    np.testing.assert_array_equal(sheet[below, 65], [250, 250, 250])  # image 4: row 1, col 1
    np.testing.assert_array_equal(sheet[below, 125], [32, 32, 32])  # empty slot
    assert np.any(sheet[:LABEL_BAR_PX, :60] > 200)  # label text drawn in the bar
    unlabelled = contact_sheet(images, cols=3)
    assert not np.any(unlabelled[:LABEL_BAR_PX, :60] > 200)


def test_contact_sheet_rejects_bad_input() -> None:
    image = np.zeros((4, 4, 3), np.uint8)
    with pytest.raises(InputError, match='no images'):
        contact_sheet([], cols=2)
    with pytest.raises(InputError, match='cols must be >= 1'):
        contact_sheet([image], cols=0)
    with pytest.raises(InputError, match='1 labels for 2 images'):
        contact_sheet([image, image], cols=2, labels=['a'])
