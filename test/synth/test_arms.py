"""Arms: from each wrist to a shoulder below the eyes, with the arm's lengths kept."""

from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.synth import arms
import numpy as np
import pytest

#: Eyes 1.3 m above the floor looking along world +x, pitched down 30 degrees (OpenCV axes).
PITCH = np.radians(30.0)
EYES = np.eye(4)
EYES[:3, :3] = np.stack([[0.0, -1.0, 0.0],
                         [-np.sin(PITCH), 0.0, -np.cos(PITCH)],
                         [np.cos(PITCH), 0.0, -np.sin(PITCH)]], axis=1)
EYES[:3, 3] = [0.0, 0.0, 1.3]


@pytest.fixture
def style() -> arms.ArmStyle:
    return arms.sample_arm_style(np.random.default_rng(3))


@pytest.mark.parametrize('side', [LEFT, RIGHT])
def test_a_reachable_wrist_keeps_the_arm_lengths_and_the_elbow_hangs(
        style: arms.ArmStyle, side: int) -> None:
    lateral = 0.15 if side == LEFT else -0.15  # world +y is the person's left
    wrist = np.array([0.35, lateral, 1.0])
    wrist_, hem, elbow, shoulder = arms.arm_points(wrist, EYES, side, style)
    np.testing.assert_array_equal(wrist_, wrist)
    assert np.linalg.norm(elbow - shoulder) == pytest.approx(style.lengths_m[0])
    assert np.linalg.norm(wrist - elbow) == pytest.approx(style.lengths_m[1])
    assert shoulder[2] == pytest.approx(1.3 - arms.SHOULDER_OFFSET_M[0])
    assert shoulder[0] < 0.0 and np.sign(shoulder[1]) == np.sign(lateral)  # behind, own side
    midpoint = 0.5 * (wrist + shoulder)
    assert elbow[2] < midpoint[2]  # bent downwards
    np.testing.assert_allclose(hem, wrist + style.hem_fraction * (elbow - wrist))


def test_a_wrist_out_of_reach_straightens_the_arm(style: arms.ArmStyle) -> None:
    wrist = np.array([1.5, 0.2, 1.0])
    _, _, elbow, shoulder = arms.arm_points(wrist, EYES, LEFT, style)
    upper, fore = style.lengths_m
    np.testing.assert_allclose(elbow, shoulder + (wrist - shoulder) * upper / (upper + fore))


def test_styles_are_drawn_within_their_ranges() -> None:
    rng = np.random.default_rng(0)
    for _ in range(20):
        style = arms.sample_arm_style(rng)
        assert arms.HEM_FRACTION_RANGE[0] <= style.hem_fraction <= arms.HEM_FRACTION_RANGE[1]
        scale = style.lengths_m[0] / arms.ARM_LENGTHS_M[0]
        assert arms.ARM_SCALE_RANGE[0] <= scale <= arms.ARM_SCALE_RANGE[1]
        np.testing.assert_allclose(style.radii_m, np.asarray(arms.ARM_RADII_M) * scale)
        assert all(0 <= c <= 255 for c in style.sleeve_rgb)
