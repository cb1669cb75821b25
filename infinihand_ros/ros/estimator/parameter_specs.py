"""Descriptions and ranges of the estimator node's parameters (their defaults: the YAML file).

One ``ParameterSpec`` per parameter of ``config/estimator.yaml``; the node turns each into an
rclpy ``ParameterDescriptor`` (rclpy then enforces the type and the numeric range, also for
values from a params file). Choices of string parameters are checked by ``EstimatorConfig``.
"""

from dataclasses import dataclass
from typing import Final


@dataclass(frozen=True)
class ParameterSpec:
    """What a parameter means and which values it takes.

    Attributes:
        description: one sentence shown by parameter tools.
        low: smallest value of a numeric parameter (None: no range).
        high: largest value of a numeric parameter.

    """

    description: str
    low: float | None = None
    high: float | None = None


_BIG: Final = 1e9
_BIG_INT: Final = 2 ** 31 - 1

PARAMETER_SPECS: Final = {
    'engine.config': ParameterSpec('Engine YAML (config/engine.yaml layout); empty: the '
                                   "package's config/engine.yaml."),
    'engine.checkpoint': ParameterSpec('Whole-model checkpoint directory; empty: the engine '
                                       "config's (bundled) model."),
    'engine.device': ParameterSpec('Torch device: cpu, cuda or cuda:N.'),
    'engine.mode': ParameterSpec('per_frame (lowest latency) or windowed (throughput).'),
    'engine.keyframe_interval': ParameterSpec('After the anchors, every n-th frame enters the '
                                              'streaming memory.', 1, _BIG_INT),
    'engine.bundle_adjustment': ParameterSpec("off, in_process (the engine's background "
                                              'bundle-adjustment worker) or node (the '
                                              'bundle_adjustment node refines keyframes).'),
    'frames.world_frame_id': ParameterSpec('Frame id of every world-frame output.'),
    'frames.camera_frame_id': ParameterSpec('Camera (optical) frame id; empty: the image '
                                            "header's frame id."),
    'camera.motion': ParameterSpec('estimate (moving camera) or static (fixed camera: the pose '
                                   'is held at identity, no SLAM needed).'),
    'camera.info_tolerance_s': ParameterSpec('A CameraInfo pairs with an image whose stamp is '
                                             'at most this far from its own, s.', 0.0, 3600.0),
    'camera.info_wait_s': ParameterSpec('Once CameraInfos arrive, an image waits at most this '
                                        'long for its own (it may come just after it), s.', 0.0,
                                        10.0),
    'camera.fallback.fx': ParameterSpec('Fallback focal length x when no CameraInfo pairs, px; '
                                        "0.0 (with fy 0.0): use the model's field of view.",
                                        0.0, _BIG),
    'camera.fallback.fy': ParameterSpec('Fallback focal length y, px; 0.0: none.', 0.0, _BIG),
    'camera.fallback.cx': ParameterSpec('Fallback principal point x, px; 0.0: the image '
                                        'centre.', 0.0, _BIG),
    'camera.fallback.cy': ParameterSpec('Fallback principal point y, px; 0.0: the image '
                                        'centre.', 0.0, _BIG),
    'outputs.camera_pose': ParameterSpec('Publish ~/camera_pose.'),
    'outputs.camera_path': ParameterSpec('Publish ~/camera_path (latched).'),
    'outputs.hands': ParameterSpec('Publish ~/hands/{left,right}/{wrist_pose,landmarks,'
                                   'wrist_frame_landmarks}.'),
    'outputs.markers': ParameterSpec('Publish ~/hands/markers.'),
    'outputs.camera_info': ParameterSpec('Publish ~/camera_info (the intrinsics used).'),
    'outputs.path_length': ParameterSpec('Poses kept in ~/camera_path.', 1, 1_000_000),
    'smoothing.mode': ParameterSpec('Smoothing of the hand outputs: off or one_euro.'),
    'smoothing.min_cutoff_hz': ParameterSpec('One-Euro minimum cutoff frequency, Hz.', 1e-6,
                                             1000.0),
    'smoothing.beta': ParameterSpec('One-Euro speed coefficient (0: a fixed low-pass).', 0.0,
                                    1000.0),
    'smoothing.d_cutoff_hz': ParameterSpec('One-Euro cutoff of the speed estimate, Hz.', 1e-6,
                                           1000.0),
    'identity.match_radius': ParameterSpec('A hand this close to a track (fraction of the '
                                           'image diagonal) continues it.', 1e-6, 10.0),
    'identity.max_gap_s': ParameterSpec('A hand track unseen for longer is forgotten, s.', 1e-6,
                                        3600.0),
    'shape.enabled': ParameterSpec('Share one hand shape (MANO betas) per side over time.'),
    'shape.min_confidence': ParameterSpec('Only hands at least this confident shape the shared '
                                          'estimate.', 0.0, 1.0),
    'shape.min_samples': ParameterSpec('Confident hands needed before the shared shape is '
                                       'used.', 1, _BIG_INT),
    'diagnostics.period_s': ParameterSpec('/diagnostics publishing period, s.', 1e-3, 3600.0),
    'diagnostics.window_s': ParameterSpec('Rates and latency percentiles cover this much recent '
                                          'time, s.', 1e-3, 3600.0),
    'ba_node.timeout_s': ParameterSpec('With engine.bundle_adjustment node: the BA node counts '
                                       'as lost when its status has not come for this long, s.',
                                       1e-3, 3600.0),
    'bad_frame_log_period_s': ParameterSpec('Throttle of the bad-frame warning, s.', 1e-3,
                                            3600.0),
}
