"""A fixed camera's lens estimated beside the stream (``engine/lens_warmup.py``)."""

import threading

from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.engine.lens_warmup import LensWarmup
from infinihand_ros.engine.lens_warmup import NOMINAL_HFOV_DEG
from infinihand_ros.engine.lens_warmup import nominal_intrinsics
import numpy as np
import pytest

WIDTH, HEIGHT = 64, 48


def _image(value: int) -> np.ndarray:
    return np.full((HEIGHT, WIDTH, 3), value, np.uint8)


def _lens(fx: float) -> Intrinsics:
    return Intrinsics(fx, fx, 31.5, 23.5, WIDTH, HEIGHT)


def test_nominal_lens_has_the_nominal_field_of_view():
    lens = nominal_intrinsics(640, 480)
    assert np.degrees(2 * np.arctan(320 / lens.fx)) == pytest.approx(NOMINAL_HFOV_DEG)
    assert (lens.cx, lens.cy) == (319.5, 239.5)


def test_beside_answers_at_once_and_settles_on_the_median():
    release = threading.Event()
    seen = []

    def predict(image: np.ndarray) -> Intrinsics:
        release.wait(10.0)
        seen.append(int(image[0, 0, 0]))
        return _lens(100.0 + 10.0 * len(seen))

    warmup = LensWarmup(predict, wanted=3, beside=True)
    try:
        assert not warmup.offered  # nothing asked for yet (a camera with CameraInfo)
        lens, provisional = warmup.lens(_image(0))  # the worker is busy with this one
        assert provisional and lens == nominal_intrinsics(WIDTH, HEIGHT)
        assert warmup.lens(_image(1)) == (nominal_intrinsics(WIDTH, HEIGHT), True)
        release.set()
        warmup.drain()
        lens, provisional = warmup.lens(_image(2))  # the first prediction is in
        assert provisional and lens.fx == 110.0
        warmup.drain()
        lens, provisional = warmup.lens(_image(3))
        assert provisional and lens.fx == pytest.approx(115.0)
        warmup.drain()
        assert warmup.settled is not None and warmup.settled.fx == 120.0  # median of 3
        assert warmup.lens(_image(4)) == (warmup.settled, False)
        assert seen == [0, 2, 3]  # busy: frame 1 was not predicted
        warmup.reset()
        assert warmup.settled is None and not warmup.offered
    finally:
        warmup.close()


def test_first_predicts_in_the_callers_thread_in_order():
    calls = []

    def predict(image: np.ndarray) -> Intrinsics:
        calls.append(threading.current_thread())
        return _lens(100.0 * len(calls))

    warmup = LensWarmup(predict, wanted=2, beside=False)
    assert warmup.lens(_image(0)) == (_lens(100.0), True)
    lens, provisional = warmup.lens(_image(1))
    assert not provisional and lens.fx == 150.0
    assert warmup.lens(_image(2)) == (lens, False)
    assert calls == [threading.current_thread()] * 2
    warmup.close()
