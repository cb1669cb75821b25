"""Frame checks give clear errors; every preprocessing mode keeps the geometry exact both ways."""

import cv2
from infinihand_ros.core import distortion
from infinihand_ros.core import geometry
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
from infinihand_ros.engine.frame_input import check_image
from infinihand_ros.engine.frame_input import check_intrinsics
from infinihand_ros.engine.frame_input import fit_image
from infinihand_ros.engine.frame_input import LensRectifier
from infinihand_ros.engine.frame_input import letterbox
from infinihand_ros.engine.frame_input import model_size_for
from infinihand_ros.model.config import AggregatorConfig
from infinihand_ros.model.config import PREPROCESSING_MODES
import numpy as np
import pytest

#: The paper input (518 wide, 518x378 letterbox) and the tiny one (224 wide, 224x168).
PAPER = AggregatorConfig(image_height=378, image_width=518, embed_dim=192, num_heads=3)
TINY = AggregatorConfig()
SOURCES = [(640, 480), (1920, 1080), (480, 640)]


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


@pytest.mark.parametrize(('config', 'expected'), [
    # Upstream: height round(h * 518 / w / 14) * 14, cropped to 518 (crop) or padded (pad).
    (PAPER, {'resize_crop': [(518, 392), (518, 294), (518, 518)],
             'resize_pad': [(518, 518)] * 3, 'letterbox': [(518, 378)] * 3}),
    (TINY, {'resize_crop': [(224, 168), (224, 126), (224, 224)],
            'resize_pad': [(224, 224)] * 3, 'letterbox': [(224, 168)] * 3}),
])
def test_model_sizes_of_each_mode(config: AggregatorConfig, expected: dict) -> None:
    for mode, sizes in expected.items():
        for (width, height), size in zip(SOURCES, sizes):
            assert model_size_for(width, height, mode, config) == size, (mode, width, height)
            image, _ = fit_image(np.zeros((height, width, 3), np.uint8), mode, config)
            assert image.shape == (size[1], size[0], 3) and image.dtype == np.uint8
            assert size[0] % config.patch_size == 0 and size[1] % config.patch_size == 0


@pytest.mark.parametrize('mode', PREPROCESSING_MODES)
@pytest.mark.parametrize('source_size', SOURCES + [(300, 500), (518, 378)])
def test_projections_and_points_are_exact_both_ways(mode: str, source_size: tuple[int, int],
                                                    rng: np.random.Generator) -> None:
    width, height = source_size
    intrinsics = Intrinsics(0.8 * width, 0.8 * width, width / 2 - 3.0, height / 2 + 2.0,
                            width, height)
    points = rng.uniform([-0.3, -0.2, 1.0], [0.3, 0.2, 2.0], size=(50, 3))
    image, mapping = fit_image(np.zeros((height, width, 3), np.uint8), mode, PAPER)
    model_intrinsics = mapping.intrinsics_to_model(intrinsics)
    assert (model_intrinsics.width, model_intrinsics.height) == (image.shape[1], image.shape[0])
    in_model = geometry.project_points(points, model_intrinsics.matrix())
    in_source = geometry.project_points(points, intrinsics.matrix())
    np.testing.assert_allclose(mapping.points_to_model(in_source), in_model, atol=1e-9)
    np.testing.assert_allclose(mapping.points_to_source(in_model), in_source, atol=1e-9)
    back = mapping.intrinsics_to_source(model_intrinsics)
    np.testing.assert_allclose(back.matrix(), intrinsics.matrix(), atol=1e-9)


@pytest.mark.parametrize('mode', PREPROCESSING_MODES)
def test_pixels_land_where_the_mapping_says(mode: str) -> None:
    """A bright square's centre in the model image maps back to its source centre."""
    source = np.zeros((480, 640, 3), np.uint8)
    source[200:260, 300:380] = 255  # centred on pixel (339.5, 229.5)
    image, mapping = fit_image(source, mode, TINY)
    gray = image[:, :, 0].astype(np.float64)
    if mode == 'resize_pad':
        gray[:mapping.content_box[1]] = 0.0  # the white padding
        gray[mapping.content_box[3]:] = 0.0
    rows, cols = np.nonzero(gray > 127)
    centre = mapping.points_to_source(np.array([cols.mean(), rows.mean()]))
    np.testing.assert_allclose(centre, [339.5, 229.5], atol=1.0)


def test_padding_is_black_for_letterbox_and_white_for_resize_pad() -> None:
    source = np.full((100, 200, 3), 128, np.uint8)
    boxed, box_mapping = letterbox(source, (100, 100))
    assert boxed[:20].max() == 0 and boxed[80:].max() == 0  # symmetric bars above and below
    assert box_mapping.content_box == (0, 25, 100, 75)
    padded, pad_mapping = fit_image(source, 'resize_pad', TINY)
    top = pad_mapping.content_box[1]
    assert padded.shape == (224, 224, 3) and top == (224 - 112) // 2
    assert padded[:top].min() == 255 and padded[pad_mapping.content_box[3]:].min() == 255
    assert abs(int(padded[112, 112, 0]) - 128) <= 1


@pytest.mark.parametrize('mode', PREPROCESSING_MODES)
def test_dense_maps_come_back_exactly_and_crops_as_nan(mode: str) -> None:
    """A map linear in model pixels comes back as the same linear function of source pixels."""
    width, height = 480, 640  # portrait: resize_crop cuts rows away, the others pad
    _, mapping = fit_image(np.zeros((height, width, 3), np.uint8), mode, TINY)
    model_width, model_height = mapping.model_size
    v_model, u_model = np.mgrid[0:model_height, 0:model_width].astype(np.float64)
    values = np.stack((u_model, v_model), axis=-1)
    back = mapping.map_to_source(values)
    assert back.shape == (height, width, 2) and back.dtype == np.float64
    v_source, u_source = np.mgrid[0:height, 0:width].astype(np.float64)
    expected = mapping.points_to_model(np.stack((u_source, v_source), axis=-1))
    x0, y0, x1, y1 = mapping.content_box
    inside = ((expected[..., 0] >= x0) & (expected[..., 0] <= x1 - 1)
              & (expected[..., 1] >= y0) & (expected[..., 1] <= y1 - 1))
    np.testing.assert_allclose(back[inside], expected[inside], atol=1e-9)
    cut = np.isnan(back[..., 0])
    if mode == 'resize_crop':  # 640 rows -> 686 -> centre 224 kept: the top and bottom are cut
        assert cut[0].all() and cut[-1].all() and not cut[height // 2].any()
        assert not cut[inside].any()
    else:
        assert not cut.any()
    filled = mapping.map_to_source(values[..., 0].astype(np.float32), fill=-1.0)
    assert filled.dtype == np.float32 and (filled[cut] == -1.0).all()


def test_bad_mode_map_size_and_aspect_are_refused() -> None:
    image = np.zeros((48, 64, 3), np.uint8)
    with pytest.raises(InputError, match="got 'crop'"):
        fit_image(image, 'crop', TINY)
    _, mapping = fit_image(image, 'resize_crop', TINY)
    with pytest.raises(InputError, match=r'expected a \(168, 224, \.\.\.\) model-size map'):
        mapping.map_to_source(np.zeros((10, 10)))
    with pytest.raises(InputError, match='less than one 14-px patch'):
        model_size_for(4000, 100, 'resize_crop', TINY)


@pytest.mark.parametrize('model, coefficients', [
    ('plumb_bob', (-0.25, 0.08, 0.0, 0.0, 0.0)),
    ('equidistant', (0.05, -0.01, 0.003, -0.001)),
])
def test_rectifier_puts_distorted_points_at_their_pinhole_pixels(model: str,
                                                                 coefficients: tuple) -> None:
    """Dots drawn where the lens projects points land where K alone projects them."""
    lens = Intrinsics(300, 305, 161, 118, 320, 240, model, coefficients)
    points = np.array([[0.3, -0.2, 1.0], [-0.35, 0.25, 1.2], [0.0, 0.0, 1.0]])
    distorted = distortion.project_points(points, lens.matrix(), model, coefficients)
    image = np.zeros((240, 320, 3), np.uint8)
    for x, y in distorted:
        cv2.circle(image, (int(round(x * 16)), int(round(y * 16))), 2 * 16, (255, 255, 255), -1,
                   cv2.LINE_AA, 4)
    rectifier = LensRectifier()
    rectified = rectifier.rectify(image, lens)
    pinhole = geometry.project_points(points, lens.matrix())
    for x, y in pinhole:
        window = rectified[int(y) - 6:int(y) + 7, int(x) - 6:int(x) + 7, 0].astype(float)
        ys, xs = np.nonzero(window)
        centre = (np.average(xs, weights=window[ys, xs]) + int(x) - 6,
                  np.average(ys, weights=window[ys, xs]) + int(y) - 6)
        np.testing.assert_allclose(centre, (x, y), atol=0.25)
    assert rectifier.rectify_like_last(image).tobytes() == rectified.tobytes()


def test_rectifier_leaves_pinhole_frames_alone() -> None:
    """No intrinsics, a pinhole lens or zero coefficients: the same array back."""
    image = np.zeros((240, 320, 3), np.uint8)
    rectifier = LensRectifier()
    for lens in (None, Intrinsics(300, 305, 161, 118, 320, 240),
                 Intrinsics(300, 305, 161, 118, 320, 240, 'plumb_bob', (0.0,) * 5)):
        assert rectifier.rectify(image, lens) is image
    assert rectifier.rectify_like_last(image) is image
    with pytest.raises(InputError, match='intrinsics are for 640x480 px but the image is 320x240'):
        rectifier.rectify(image, Intrinsics(600, 600, 320, 240, 640, 480, 'plumb_bob',
                                            (0.1, 0, 0, 0, 0)))
