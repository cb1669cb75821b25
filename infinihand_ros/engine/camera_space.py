"""A block's model output split into per-frame, camera-space records in source-image pixels.

``split_frames`` turns one ``CameraSpaceOutput`` into one ``CameraSpaceFrame`` per frame: the raw
network pose (model units), the intrinsics used (source image), the detected hands in the camera
frame (2D joints and boxes mapped back to source pixels), the frame's model depth on demand
(``FrameDepth``: the depth head runs only for the frames whose depth is used) and what the
camera tracker sees (the model-input grey image with its depth and intrinsics). ``depth_ratios``
gives the metric scale's samples of a frame's hands. No world frame and no metric scale here:
those are the pose track's (``engine/pose_track.py``) and ``engine/world_placement.py``'s.
"""

from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass
from dataclasses import replace

from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.engine.camera_tracker import TrackingView
from infinihand_ros.engine.frame_input import FrameMapping
from infinihand_ros.engine.hands.detections import FrameDetections
from infinihand_ros.engine.metric_scale import hand_depth_ratios
from infinihand_ros.model.geometry_model import GeometryModel
from infinihand_ros.model.geometry_model import GeometryOutput
from infinihand_ros.model.infinihand_model import CameraSpaceOutput
import numpy as np
import torch


@dataclass(frozen=True)
class PreparedFrame:
    """A checked frame waiting for the model.

    Attributes:
        index: 0-based index in the stream.
        timestamp_ns: the source image's stamp.
        pixels: (3, H, W) float32 RGB in [0, 1] at the model size; None for a frame that goes
            on without the model (a fixed camera with hands found outside it).
        mapping: mapping between source and model pixels (None with ``pixels``).
        intrinsics: the given source intrinsics, or None (the model's FoV is used).
        keyframe: whether the frame enters the streaming memory.
        source_image: a copy of the source RGB image when bundle adjustment needs it, else None.
        detections: the hand source's detection in the source image, started when the frame
            was pushed (``HandSource.detect`` in the engine's detection thread, beside the
            model), or None when the source reads no image; ``found()`` waits for it.
        provisional_lens: ``intrinsics`` is a fixed camera's provisional lens (still being
            estimated beside the stream: ``engine/lens_warmup.py``).

    """

    index: int
    timestamp_ns: int
    pixels: torch.Tensor | None
    mapping: FrameMapping | None
    intrinsics: Intrinsics | None
    keyframe: bool
    source_image: np.ndarray | None = None
    detections: Future | None = None
    provisional_lens: bool = False

    def found(self) -> FrameDetections:
        """Return what the hand source found in the frame (waits for it; empty without one)."""
        return FrameDetections() if self.detections is None else self.detections.result()


class FrameDepth:
    """A frame's model-size depth, computed on first use and kept.

    The depth head runs only where a depth is used: tracker references, metric-scale samples,
    keyframes for BA.
    """

    def __init__(self, compute: Callable[[], torch.Tensor]) -> None:
        """Hold ``compute``, which returns the (H, W) model depth (model units)."""
        self._compute: Callable[[], torch.Tensor] | None = compute
        self._depth: np.ndarray | None = None

    @property
    def computed(self) -> bool:
        """Return whether the depth has been computed."""
        return self._depth is not None

    def model(self) -> np.ndarray:
        """Return the (H, W) float32 depth at the model size, model units."""
        if self._depth is None:
            with torch.inference_mode():
                self._depth = self._compute().detach().float().cpu().numpy()
            self._compute = None  # lets go of the block's tokens
        return self._depth


@dataclass(frozen=True)
class CameraSpaceFrame:
    """One frame's camera-space estimate, before scale, BA and world placement.

    Attributes:
        frame: the input frame.
        T_raw: (4, 4) camera-to-world network pose, model units; None on a frame the
            geometry branch skipped between geometry frames (tracked from the image alone).
        intrinsics: the intrinsics used, for the source image.
        hands: detected hands (camera frame, metres; pixels of the source image).
        depth: the frame's model depth on demand, or None when the geometry branch did not run
            on the frame (a fixed camera with hands found outside the model).
        view: what the camera tracker needs (model-input grey image, depth, intrinsics),
            without hand boxes yet; None when no tracker runs.

    """

    frame: PreparedFrame
    T_raw: np.ndarray | None
    intrinsics: Intrinsics
    hands: tuple[HandState, ...]
    depth: FrameDepth | None
    view: TrackingView | None


def tracking_view(frame: PreparedFrame, depth: FrameDepth | None,
                  intrinsics_model: np.ndarray, size: tuple[int, int]) -> TrackingView:
    """Return the tracker's view of a frame: grey model input, depth on demand, (3, 3) K.

    ``size`` is the model input's (height, width); ``depth`` is None on a frame without the
    geometry branch.
    """
    height, width = size
    weights = torch.tensor([0.299, 0.587, 0.114], dtype=frame.pixels.dtype,
                           device=frame.pixels.device)
    gray = torch.tensordot(weights, frame.pixels, dims=1).mul(255.0).round().clamp(0, 255)
    return TrackingView(gray.to(torch.uint8).cpu().numpy(),
                        None if depth is None else depth.model,
                        Intrinsics.from_matrix(intrinsics_model, width, height),
                        frame.mapping.content_box, np.zeros((0, 4)))


def _numpy(tensor: torch.Tensor) -> np.ndarray:
    return tensor.detach().double().cpu().numpy()


def _depths(model: GeometryModel | None, geometry: GeometryOutput, count: int
            ) -> list[FrameDepth]:
    """Return each frame's depth on demand: from the block's depth or its kept tokens.

    ``model`` computes it from the tokens when the block skipped the depth head.
    """
    if geometry.depth is not None:
        return [FrameDepth(lambda row=row: geometry.depth[0, row]) for row in range(count)]
    return [FrameDepth(lambda row=row: model.frame_depth(geometry.dense_input, row))
            for row in range(count)]


def split_frames(output: CameraSpaceOutput, frames: list[PreparedFrame],
                 model: GeometryModel | None, views: bool = True) -> list[CameraSpaceFrame]:
    """Return one record per frame of a B=1 block, in order (``views``: with tracker views).

    ``model`` is the geometry branch that computes depth on demand (None when the block's
    outputs hold the depth).
    """
    hands = output.hands
    frame_of_hand = output.boxes.batch_index.cpu().numpy()
    columns = {name: _numpy(value) for name, value in (
        ('orient', hands.mano_cam.global_orient), ('pose', hands.mano_cam.hand_pose),
        ('betas', hands.mano_cam.betas), ('transl', hands.mano_cam.transl),
        ('joints', hands.joints_cam), ('joints_2d', hands.joints_2d),
        ('boxes', output.boxes.boxes_xyxy), ('presence', output.presence))}
    sides = output.boxes.sides.cpu().numpy()
    poses = _numpy(output.T_world_cam[0])
    intrinsics = _numpy(output.intrinsics[0])
    size = tuple(frames[0].pixels.shape[-2:])  # model input (height, width)
    depths = _depths(model, output.geometry, len(frames))
    records = []
    for row, frame in enumerate(frames):
        mapping = frame.mapping
        rows = np.flatnonzero(frame_of_hand == row)
        states = tuple(HandState(
            side=int(sides[r]),
            mano_cam=ManoParams(columns['orient'][r], columns['pose'][r], columns['betas'][r],
                                columns['transl'][r]),
            joints_cam=columns['joints'][r],
            joints_2d=mapping.points_to_source(columns['joints_2d'][r]),
            box_xyxy=mapping.points_to_source(columns['boxes'][r].reshape(2, 2)).reshape(4),
            confidence=float(np.clip(columns['presence'][r], 0.0, 1.0))) for r in rows)
        used = frame.intrinsics or mapping.intrinsics_to_source(
            Intrinsics.from_matrix(intrinsics[row], size[1], size[0]))
        view = tracking_view(frame, depths[row], intrinsics[row], size) if views else None
        records.append(CameraSpaceFrame(frame, poses[row], used, states, depths[row], view))
    return records


def split_geometry(geometry: GeometryOutput, T_world_cam: torch.Tensor,
                   intrinsics: torch.Tensor, frames: list[PreparedFrame],
                   model: GeometryModel | None, views: bool = True) -> list[CameraSpaceFrame]:
    """Return one hand-less record per frame of a B=1 block (a source outside the model).

    As ``split_frames`` without the hand branch: the raw pose, the intrinsics used and the
    depth on demand.
    """
    poses = _numpy(T_world_cam[0])
    matrices = _numpy(intrinsics[0])
    size = tuple(frames[0].pixels.shape[-2:])  # model input (height, width)
    depths = _depths(model, geometry, len(frames))
    records = []
    for row, frame in enumerate(frames):
        used = frame.intrinsics or frame.mapping.intrinsics_to_source(
            Intrinsics.from_matrix(matrices[row], size[1], size[0]))
        view = tracking_view(frame, depths[row], matrices[row], size) if views else None
        records.append(CameraSpaceFrame(frame, poses[row], used, (), depths[row], view))
    return records


def depth_ratios(depth: np.ndarray, frame: PreparedFrame, hands: tuple[HandState, ...]
                 ) -> np.ndarray:
    """Return (N,) metric-to-model depth ratios of a frame's hands (the metric scale's samples).

    ``depth`` is the frame's (H, W) model depth at the model size.
    """
    if not hands:
        return np.zeros(0)
    joints_2d = np.stack([frame.mapping.points_to_model(hand.joints_2d) for hand in hands])
    depths = np.stack([hand.joints_cam[:, 2] for hand in hands])
    return _numpy(hand_depth_ratios(torch.as_tensor(depth, dtype=torch.float64)[None],
                                    torch.zeros(len(hands), dtype=torch.long),
                                    torch.as_tensor(joints_2d, dtype=torch.float64),
                                    torch.as_tensor(depths, dtype=torch.float64)))


def with_hand_boxes(view: TrackingView, frame: PreparedFrame,
                    hands: tuple[HandState, ...]) -> TrackingView:
    """Return ``view`` with the hands' boxes in model-input pixels (never tracked)."""
    boxes = [frame.mapping.points_to_model(hand.box_xyxy.reshape(2, 2)).reshape(4)
             for hand in hands]
    return replace(view, hand_boxes=np.array(boxes).reshape(-1, 4))
