"""Topic and frame names used in bags and by the nodes (one place, no literals elsewhere)."""

from typing import Final

#: Camera input of recorded and synthetic bags.
IMAGE_TOPIC: Final = '/camera/image_raw'
COMPRESSED_IMAGE_TOPIC: Final = '/camera/image_raw/compressed'
CAMERA_INFO_TOPIC: Final = '/camera/camera_info'
#: Ground truth written by the synthetic generator.
GT_CAMERA_POSE_TOPIC: Final = '/ground_truth/camera_pose'
GT_HANDS_TOPIC: Final = '/ground_truth/hands'

#: Frame ids: the OpenCV optical camera frame and the world frame (the first camera's).
CAMERA_FRAME_ID: Final = 'camera_optical_frame'
WORLD_FRAME_ID: Final = 'world'
