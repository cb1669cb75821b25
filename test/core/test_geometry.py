"""Tests of the numpy geometry helpers against hand-computed cases and properties."""

from infinihand_ros.core import geometry
import numpy as np
import pytest


def test_axis_angle_round_trip_and_known_rotation(rng: np.random.Generator) -> None:
    quarter_turn_z = geometry.axis_angle_to_matrix(np.array([0.0, 0.0, np.pi / 2]))
    np.testing.assert_allclose(quarter_turn_z @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)
    aa = rng.normal(size=(4, 5, 3)) * 0.8
    back = geometry.matrix_to_axis_angle(geometry.axis_angle_to_matrix(aa))
    assert back.shape == (4, 5, 3)
    np.testing.assert_allclose(back, aa, atol=1e-9)


def test_quaternions_are_xyzw() -> None:
    # 90 degrees about z: (x, y, z, w) = (0, 0, sin 45, cos 45).
    quat = geometry.matrix_to_quaternion_xyzw(geometry.axis_angle_to_matrix([0, 0, np.pi / 2]))
    np.testing.assert_allclose(quat, [0, 0, np.sqrt(0.5), np.sqrt(0.5)], atol=1e-12)
    np.testing.assert_allclose(geometry.quaternion_xyzw_to_matrix(quat),
                               geometry.axis_angle_to_matrix([0, 0, np.pi / 2]), atol=1e-12)


def test_rotation_angle_deg() -> None:
    rot = geometry.axis_angle_to_matrix(np.array([[0.0, np.radians(30.0), 0.0]]))
    np.testing.assert_allclose(geometry.rotation_angle_deg(rot, np.eye(3)), [30.0], atol=1e-9)
    np.testing.assert_allclose(geometry.rotation_angle_deg(rot, rot), [0.0], atol=1e-5)


def test_similarity_recovers_a_known_transform(rng: np.random.Generator) -> None:
    source = rng.normal(size=(3, 21, 3))
    rotation = geometry.axis_angle_to_matrix(rng.normal(size=(3, 3)))
    scale = np.array([0.5, 1.0, 2.0])
    translation = rng.normal(size=(3, 3))
    target = geometry.apply_similarity(source, scale, rotation, translation)
    fit_scale, fit_rotation, fit_translation = geometry.similarity_transform(source, target)
    np.testing.assert_allclose(fit_scale, scale, atol=1e-9)
    np.testing.assert_allclose(fit_rotation, rotation, atol=1e-9)
    np.testing.assert_allclose(fit_translation, translation, atol=1e-9)
    np.testing.assert_allclose(geometry.align_similarity(source, target), target, atol=1e-9)


def test_similarity_never_reflects(rng: np.random.Generator) -> None:
    source = rng.normal(size=(21, 3))
    mirrored = source * np.array([-1.0, 1.0, 1.0])
    _, rotation, _ = geometry.similarity_transform(source, mirrored)
    assert np.linalg.det(rotation) == pytest.approx(1.0)
    assert not np.allclose(geometry.align_similarity(source, mirrored), mirrored, atol=1e-3)


def test_project_points_pinhole_and_depth_floor() -> None:
    k = np.array([[500.0, 0, 320], [0, 400.0, 240], [0, 0, 1]])
    # (0.1, -0.2, 2): u = 500*0.05 + 320 = 345, v = 400*(-0.1) + 240 = 200.
    np.testing.assert_allclose(geometry.project_points([0.1, -0.2, 2.0], k), [345.0, 200.0])
    # Behind the camera: depth floored at 1 cm, so x/z = 0.1/0.01 = 10.
    np.testing.assert_allclose(geometry.project_points([0.1, 0.0, -1.0], k), [5320.0, 240.0])
    batched = geometry.project_points(np.ones((2, 21, 3)), np.stack([k, 2 * k]))
    np.testing.assert_allclose(batched[1, 0], [2 * 500 + 640, 2 * 400 + 480])


def test_fov_and_focal_are_inverse() -> None:
    # 90 degrees over 200 px: f = 100 / tan(45 deg) = 100.
    assert geometry.focal_from_fov(np.pi / 2, 200) == pytest.approx(100.0)
    assert geometry.fov_from_focal(100.0, 200) == pytest.approx(np.pi / 2)


def test_transforms_invert(rng: np.random.Generator) -> None:
    transform = geometry.make_transform(geometry.axis_angle_to_matrix(rng.normal(size=3)),
                                        rng.normal(size=3))
    points = rng.normal(size=(7, 3))
    there = geometry.transform_points(transform, points)
    np.testing.assert_allclose(
        geometry.transform_points(geometry.invert_transform(transform), there), points, atol=1e-12)


def test_interpolated_transform_turns_and_moves_the_fraction_asked(
        rng: np.random.Generator) -> None:
    start = geometry.make_transform(geometry.axis_angle_to_matrix(rng.normal(size=3)),
                                    rng.normal(size=3))
    turn = geometry.axis_angle_to_matrix(np.array([0.0, 0.4, 0.0]))
    end = geometry.make_transform(start[:3, :3] @ turn, start[:3, 3] + [0.2, 0.0, -0.1])
    np.testing.assert_allclose(geometry.interpolate_transform(start, end, 0.0), start, atol=1e-12)
    np.testing.assert_allclose(geometry.interpolate_transform(start, end, 1.0), end, atol=1e-12)
    for fraction in (0.25, -0.5):  # a negative fraction extrapolates backwards
        between = geometry.interpolate_transform(start, end, fraction)
        assert geometry.rotation_angle_deg(start[:3, :3], between[:3, :3]) == pytest.approx(
            abs(fraction) * np.degrees(0.4))
        np.testing.assert_allclose(between[:3, 3], start[:3, 3] + fraction * np.array(
            [0.2, 0.0, -0.1]))
