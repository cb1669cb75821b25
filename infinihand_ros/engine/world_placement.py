"""Hands from the camera frame into the world frame (paper eq. 9): the one place this happens.

The engine calls ``place_in_world`` once per result, with the pose track's best camera pose of
that frame. MANO orientation and translation go through ``model/hand/frames.camera_to_world``
(the same eq. 9 that training uses); joints are mapped by the rigid camera pose.
"""

from dataclasses import replace

from infinihand_ros.core.datatypes import CameraPose
from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import ManoParams
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
