"""Which frames' hands are metric-scale samples, and the correction they are multiplied by.

Each sampled frame's hands give metric-to-model depth ratios (``camera_space.depth_ratios``),
multiplied by the hand-depth correction (configured, or the checkpoint's measured value); the
pose track's scale estimate takes them (``PoseTrack.observe_scale``).
"""

from infinihand_ros.engine.camera_space import CameraSpaceFrame
from infinihand_ros.engine.camera_space import depth_ratios
from infinihand_ros.engine.metric_scale import MetricScaleConfig
from infinihand_ros.model.io.bundled import hand_depth_correction
from infinihand_ros.model.io.bundled import resolve_checkpoint
import numpy as np


def scale_correction(config: MetricScaleConfig, checkpoint: str | None) -> float:
    """Return the hand-depth correction of the metric scale: configured, or the checkpoint's.

    Args:
        config: the metric-scale settings (``hand_depth_correction``, None: the checkpoint's).
        checkpoint: the engine's checkpoint (a bundled name or a directory), None for none (1).

    """
    if config.hand_depth_correction is not None:
        return config.hand_depth_correction
    return 1.0 if checkpoint is None else hand_depth_correction(resolve_checkpoint(checkpoint))


def scale_samples(record: CameraSpaceFrame, depth_kept: bool, warmup: bool,
                  sample_interval: int, correction: float) -> tuple[np.ndarray, np.ndarray]:
    """Return the metric-scale samples of a frame's hands (and their unit model depths).

    On the frames that are sampled: every frame while the scale warms up (``warmup``); after
    that every ``sample_interval``-th frame and any frame whose depth is computed anyway (a
    tracker reference, or ``depth_kept``: a keyframe for BA or ``depth_maps``). Others give
    none (two empty arrays).
    """
    depth, hands = record.depth, record.hands
    if depth is None or not hands or not (
            depth.computed or depth_kept or warmup or record.frame.index % sample_interval == 0):
        return np.zeros(0), np.zeros(0)
    samples = depth_ratios(depth.model(), record.frame, hands) * correction
    return samples, np.ones(len(samples))
