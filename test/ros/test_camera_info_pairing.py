"""CameraInfo pairing by stamp, validation and fallback (ros/estimator/camera_info_pairing.py)."""

from types import SimpleNamespace

from infinihand_ros.core.errors import InputError
from infinihand_ros.ros.estimator.camera_info_pairing import CameraInfoPairing
from infinihand_ros.ros.estimator.camera_info_pairing import fallback_intrinsics
from infinihand_ros.ros.estimator.camera_info_pairing import FROM_CAMERA_INFO
from infinihand_ros.ros.estimator.camera_info_pairing import FROM_FALLBACK
from infinihand_ros.ros.estimator.camera_info_pairing import FROM_MODEL
from infinihand_ros.ros.estimator.config import FallbackIntrinsics
import pytest

MS = 1_000_000


def info(stamp_ns: int, fx: float, width: int = 640, height: int = 480) -> SimpleNamespace:
    """Return a CameraInfo-like message with K = [[fx, 0, 320], [0, fx, 240], [0, 0, 1]]."""
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    return SimpleNamespace(header=SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=nanosec)),
                           k=[fx, 0.0, 320.0, 0.0, fx, 240.0, 0.0, 0.0, 1.0], width=width,
                           height=height)


def test_nearest_stamp_within_tolerance_and_size_is_used() -> None:
    """The info nearest the image stamp pairs; beyond the tolerance or another size: none."""
    pairing = CameraInfoPairing(10 * MS, FallbackIntrinsics())
    pairing.add(info(1000 * MS, 500.0))
    pairing.add(info(1033 * MS, 510.0))
    pairing.add(info(1033 * MS, 999.0, width=320, height=240))
    choice = pairing.intrinsics_for(1030 * MS, 640, 480)
    assert choice.source == FROM_CAMERA_INFO
    assert choice.intrinsics.fx == 510.0
    assert pairing.intrinsics_for(1005 * MS, 640, 480).intrinsics.fx == 500.0
    assert pairing.intrinsics_for(1033 * MS, 320, 240).intrinsics.fx == 999.0
    assert pairing.intrinsics_for(1100 * MS, 640, 480).source == FROM_MODEL


@pytest.mark.parametrize('fx,match', [(float('nan'), 'NaN'), (0.0, 'K is all zeros')])
def test_nan_and_zero_camera_info_are_refused(fx: float, match: str) -> None:
    """Non-finite and uncalibrated (zero) K raise, naming the stamp, and nothing is stored."""
    pairing = CameraInfoPairing(10 * MS, FallbackIntrinsics())
    message = info(5 * MS, fx)
    if fx == 0.0:
        message.k = [0.0] * 9
    with pytest.raises(InputError, match=match) as error:
        pairing.add(message)
    assert str(5 * MS) in str(error.value)
    assert pairing.intrinsics_for(5 * MS, 640, 480).source == FROM_MODEL


def test_zero_focal_with_centre_is_refused() -> None:
    """A K with a principal point but zero focal lengths raises."""
    message = info(0, 0.0)
    with pytest.raises(InputError, match='focal lengths must be positive'):
        CameraInfoPairing(0, FallbackIntrinsics()).add(message)


def test_fallback_intrinsics_fill_in_and_default_to_the_centre() -> None:
    """The fallback pairs when no info does; cx, cy 0.0 mean the image centre."""
    fallback = FallbackIntrinsics(fx=400.0, fy=410.0)
    choice = CameraInfoPairing(0, fallback).intrinsics_for(0, 640, 480)
    assert choice.source == FROM_FALLBACK
    got = choice.intrinsics
    expected = (400.0, 410.0, 320.0, 240.0, 640, 480)
    assert (got.fx, got.fy, got.cx, got.cy, got.width, got.height) == expected
    explicit = fallback_intrinsics(FallbackIntrinsics(400.0, 400.0, 300.0, 200.0), 640, 480)
    assert (explicit.cx, explicit.cy) == (300.0, 200.0)
    assert fallback_intrinsics(FallbackIntrinsics(), 640, 480) is None


def test_paired_and_has_infos() -> None:
    """``paired`` ignores the fallback; ``has_infos`` tells whether infos ever came."""
    pairing = CameraInfoPairing(0, FallbackIntrinsics(fx=400.0, fy=400.0))
    assert not pairing.has_infos and pairing.paired(0, 640, 480) is None
    pairing.add(info(0, 500.0))
    assert pairing.has_infos and pairing.paired(0, 640, 480).fx == 500.0


def test_forget_after_drops_the_infos_ahead_of_a_restarted_stream() -> None:
    """After a restart at 1 s, the stream before's infos at 5 s go; those up to 1 s stay."""
    pairing = CameraInfoPairing(10 * MS, FallbackIntrinsics())
    pairing.add(info(5000 * MS, 500.0))  # the stream before
    pairing.add(info(1005 * MS, 600.0))  # the new stream's first one (within the tolerance)
    pairing.forget_after(1000 * MS)
    assert pairing.intrinsics_for(5000 * MS, 640, 480).source == FROM_MODEL
    assert pairing.intrinsics_for(1000 * MS, 640, 480).intrinsics.fx == 600.0


def test_distortion_is_paired_with_the_intrinsics() -> None:
    """distortion_model and d travel with K; an empty d is a pinhole camera."""
    pairing = CameraInfoPairing(0, FallbackIntrinsics())
    fisheye = info(0, 500.0)
    fisheye.distortion_model, fisheye.d = 'equidistant', [0.05, -0.01, 0.003, -0.001]
    pairing.add(fisheye)
    got = pairing.intrinsics_for(0, 640, 480).intrinsics
    assert (got.distortion_model, got.distortion) == ('equidistant', (0.05, -0.01, 0.003, -0.001))
    uncalibrated = info(MS, 500.0)
    uncalibrated.distortion_model, uncalibrated.d = 'plumb_bob', []
    pairing.add(uncalibrated)
    assert pairing.intrinsics_for(MS, 640, 480).intrinsics.distortion_model is None


@pytest.mark.parametrize('model, d, match', [
    ('kannala_brandt', [0.1] * 4, r"distortion model 'kannala_brandt' is not supported .*"
                                  r'publish the rectified image'),
    ('plumb_bob', [0.1, 0.0, 0.0], 'plumb_bob model takes 5 coefficients'),
])
def test_unusable_distortion_is_refused_by_name(model: str, d: list[float], match: str) -> None:
    """An unknown model or a wrong count raises naming the stamp and what to do."""
    message = info(7 * MS, 500.0)
    message.distortion_model, message.d = model, d
    pairing = CameraInfoPairing(0, FallbackIntrinsics())
    with pytest.raises(InputError, match=match) as error:
        pairing.add(message)
    assert str(7 * MS) in str(error.value)
    assert not pairing.has_infos
