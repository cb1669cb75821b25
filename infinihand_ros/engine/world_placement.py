"""Hands from the camera frame into the world frame (paper eq. 9): the one place this happens.

The engine places each result's hands once (``WorldPlacement.fields``), with the pose track's
best camera pose of that frame (the identity for a fixed camera), and again on the final
trajectory for offline runs (``WorldPlacement.on_final_trajectory``). MANO orientation and
translation go through ``model/hand/frames.camera_to_world`` (the same eq. 9 that training
uses); joints are mapped by the rigid camera pose.
"""

from dataclasses import dataclass
from dataclasses import replace

from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import FrameResult
from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.engine.pose_track import TrackedPose
from infinihand_ros.model.hand.frames import camera_to_world
import numpy as np
import torch


def place_in_world(hands: tuple[HandState, ...], pose: CameraPose) -> tuple[HandState, ...]:
    """Return ``hands`` with ``joints_world`` and ``mano_world`` for the camera pose ``pose``.

    Args:
        hands: hands with camera-frame MANO parameters and joints (metres).
        pose: camera-to-world pose of their frame (metres).

    """
    if not hands:
        return ()
    count = len(hands)

    def stacked(values: list[np.ndarray]) -> torch.Tensor:
        return torch.as_tensor(np.stack(values), dtype=torch.float64)

    orient = stacked([hand.mano_cam.global_orient for hand in hands])
    transl = stacked([hand.mano_cam.transl for hand in hands])
    # MANO rotates about its rest root joint J0; the posed wrist is J0 + transl in any frame.
    root = stacked([hand.joints_cam[0] for hand in hands]) - transl
    rotation = torch.as_tensor(pose.rotation, dtype=torch.float64).expand(count, 3, 3)
    position = torch.as_tensor(pose.translation, dtype=torch.float64).expand(count, 3)
    orient_w, transl_w = camera_to_world(orient, transl, rotation, position, root)
    return tuple(
        replace(hand, joints_world=pose.to_world(hand.joints_cam),
                mano_world=ManoParams(orient_w[row].numpy(), hand.mano_cam.hand_pose,
                                      hand.mano_cam.betas, transl_w[row].numpy()))
        for row, hand in enumerate(hands))


@dataclass(frozen=True)
class WorldPlacement:
    """A result's pose fields and world-space hands from its frame's tracked pose.

    Attributes:
        static: a fixed camera (``camera_motion: static``): its pose is the world frame.
        raw_poses: give each result the track's metric pose before BA corrections
            (``raw_camera_pose``; with a BA backend).

    """

    static: bool
    raw_poses: bool

    def fields(self, hands: tuple[HandState, ...], best: TrackedPose) -> dict[str, object]:
        """Return the ``FrameResult`` fields that follow from a tracked pose (hands placed)."""
        pose = CameraPose.identity() if self.static else best.camera_pose
        return {'camera_pose': pose,
                'hands': place_in_world(hands, pose), 'metric_scale': best.scale,
                'raw_camera_pose': best.scaled_pose if self.raw_poses else None,
                'pose_version': best.version,
                'tracking': 'static' if self.static else best.tracking}

    def on_final_trajectory(self, result: FrameResult, best: TrackedPose, ba_failed: bool,
                            episode_refined: bool = False) -> FrameResult:
        """Return ``result`` with the pose, scale and hands of ``best`` (the final trajectory).

        The output stage's identity and shared shape are kept; its smoothing (of the live
        world-frame joints) is not, as the hands are placed again with ``best``'s pose, the
        one written. Its depth is rescaled to ``best``'s metric scale; ``ba_failed`` flags a
        frame whose last BA call failed, ``episode_refined`` one whose pose carries the
        whole-episode refinement.
        """
        depth = (None if result.depth is None
                 else result.depth * (best.scale / result.metric_scale))
        return replace(result, depth=depth, ba_failed=ba_failed,
                       episode_refined=episode_refined, **self.fields(result.hands, best))
