"""Frame checks give clear errors; letterboxing keeps the projection geometry exact."""

from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
from infinihand_ros.engine.frame_input import check_image
from infinihand_ros.engine.frame_input import check_intrinsics
from infinihand_ros.engine.frame_input import letterbox
import numpy as np
import pytest


@pytest.mark.parametrize(('image', 'message'), [
    (np.zeros((0, 0, 3), np.uint8), 'empty or degenerate'),
    (np.zeros((10, 10), np.uint8), r'expected \(H, W, 3\) RGB'),
    (np.zeros((10, 10, 4), np.uint8), r'expected \(H, W, 3\) RGB'),
    (np.zeros((10, 10, 3), np.float32), 'expected uint8 pixels, got float32'),
    ([[1, 2, 3]], 'expected a numpy array, got list'),
])
def test_bad_images_are_named(image: object, message: str) -> None:
    with pytest.raises(InputError, match=message):
        check_image(image)


def test_intrinsics_must_match_the_image() -> None:
    image = np.zeros((48, 64, 3), np.uint8)
    assert check_intrinsics(None, image) is None
    with pytest.raises(InputError, match='intrinsics are for 640x480 px but the image is 64x48'):
        check_intrinsics(Intrinsics(500, 500, 320, 240, 640, 480), image)
    with pytest.raises(InputError, match='NaN or infinite'):
        Intrinsics(float('nan'), 500, 320, 240, 640, 480)


@pytest.mark.parametrize('source_size', [(640, 480), (1280, 720), (300, 500), (518, 378)])
def test_letterbox_keeps_projections_exact(rng: np.random.Generator,
                                           source_size: tuple[int, int]) -> None:
    width, height = source_size
    intrinsics = Intrinsics(0.8 * width, 0.8 * width, width / 2 - 3.0, height / 2 + 2.0,
                            width, height)
    points = rng.uniform([-0.3, -0.2, 1.0], [0.3, 0.2, 2.0], size=(50, 3))
    image, mapping = letterbox(np.zeros((height, width, 3), np.uint8), (224, 168))
    assert image.shape == (168, 224, 3)
    model_intrinsics = mapping.intrinsics_to_model(intrinsics)
    in_model = geometry.project_points(points, model_intrinsics.matrix())
    in_source = geometry.project_points(points, intrinsics.matrix())
    np.testing.assert_allclose(mapping.points_to_source(in_model), in_source, atol=1e-9)
    back = mapping.intrinsics_to_source(model_intrinsics)
    np.testing.assert_allclose(back.matrix(), intrinsics.matrix(), atol=1e-9)


def test_letterbox_places_pixels_where_the_mapping_says() -> None:
    source = np.zeros((100, 200, 3), np.uint8)
    source[40:60, 90:110] = 255  # a square centred on pixel (99.5, 49.5)
    image, mapping = letterbox(source, (100, 100))
    rows, cols = np.nonzero(image[:, :, 0] > 127)
    centre_model = np.array([cols.mean(), rows.mean()])
    np.testing.assert_allclose(mapping.points_to_source(centre_model), [99.5, 49.5], atol=0.5)
    assert image[:20].max() == 0 and image[80:].max() == 0  # symmetric padding above and below
