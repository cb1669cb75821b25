"""Tests of infinihand_ros/convert/resample.py: exact output times, nearest source frames."""

from infinihand_ros.convert.resample import resample
import pytest

MS = 1_000_000


def _pairs(stamps_ms: list[int]) -> list[tuple[int, int]]:
    return [(stamp * MS, index) for index, stamp in enumerate(stamps_ms)]


def test_downsampling_takes_nearest_frames_and_exact_times() -> None:
    """30 Hz to 10 Hz keeps every third frame; timestamps are k / fps exactly."""
    frames = list(resample(_pairs([0, 33, 67, 100, 133, 167, 200]), 10))
    assert [f.frame_index for f in frames] == [0, 1, 2]
    assert [f.timestamp_s for f in frames] == [0.0, 0.1, 0.2]
    assert [f.item for f in frames] == [0, 3, 6]
    assert [f.source_stamp_ns for f in frames] == [0, 100 * MS, 200 * MS]


def test_upsampling_repeats_source_frames() -> None:
    """A 5 Hz source at 10 Hz uses each frame for two output frames (ties go earlier)."""
    frames = list(resample(_pairs([0, 200, 400]), 10))
    assert [f.item for f in frames] == [0, 0, 1, 1, 2]
    assert [f.source_index for f in frames] == [0, 0, 1, 1, 2]


def test_count_spans_first_to_last_stamp() -> None:
    """floor((last - first) * fps) + 1 frames, starting at the first stamp (any offset)."""
    offset = 1_767_225_600_000_000_000
    stamps = [(offset + k * 95 * MS, k) for k in range(11)]  # 0.95 s
    frames = list(resample(stamps, 10))
    assert len(frames) == 10
    assert frames[-1].timestamp_s == pytest.approx(0.9)


def test_empty_and_single() -> None:
    """No source frame gives no output frame; one gives one."""
    assert list(resample([], 10)) == []
    assert [f.item for f in resample([(5, 'a')], 10)] == ['a']


def test_rejects_non_increasing_stamps() -> None:
    """Duplicates and backward stamps are the caller's to drop; resample refuses them."""
    with pytest.raises(ValueError, match='stamps must increase'):
        list(resample(_pairs([0, 100, 100]), 10))
