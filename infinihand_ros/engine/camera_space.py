"""A block's model output split into per-frame, camera-space records in source-image pixels.

``split_frames`` turns one ``CameraSpaceOutput`` into one ``CameraSpaceFrame`` per frame: the raw
network pose (model units), the intrinsics used (source image), the detected hands in the camera
frame (2D joints and boxes mapped back to source pixels), each hand's metric-to-model depth
ratio for the scale estimate, for keyframes the model depth map at the source size, and what
the camera tracker sees (the model-input grey image with its depth and intrinsics). No
world frame and no metric scale here: those are the pose track's (``engine/pose_track.py``) and
``engine/world_placement.py``'s.
"""

from dataclasses import dataclass

from infinihand_ros.core.datatypes import HandState
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.datatypes import ManoParams
from infinihand_ros.engine.camera_tracker import TrackingView
from infinihand_ros.engine.frame_input import FrameMapping
from infinihand_ros.engine.metric_scale import hand_depth_ratios
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
        pixels: (3, H, W) float32 RGB in [0, 1] at the model size.
        mapping: mapping between source and model pixels.
        intrinsics: the given source intrinsics, or None (the model's FoV is used).
        keyframe: whether the frame enters the streaming memory.
        source_image: a copy of the source RGB image when bundle adjustment needs it, else None.
        detections: what the hand source found in the source image when the frame was pushed
            (``HandSource.detect``; empty for the hand branch without its guard).

    """

    index: int
    timestamp_ns: int
    pixels: torch.Tensor
    mapping: FrameMapping
    intrinsics: Intrinsics | None
    keyframe: bool
    source_image: np.ndarray | None = None
    detections: tuple = ()


@dataclass(frozen=True)
class CameraSpaceFrame:
    """One frame's camera-space estimate, before scale, BA and world placement.

    Attributes:
        frame: the input frame.
        T_raw: (4, 4) camera-to-world pose, model units.
        intrinsics: the intrinsics used, for the source image.
        hands: detected hands (camera frame, metres; pixels of the source image).
        depth_ratios: (N,) per hand, metric joint depth / model depth (median over joints).
        depth_model: (H, W) float32 model-unit depth at the source size for keyframes, else
            None (pixels a crop cut away are NaN).
        view: what the camera tracker needs (model-input grey image, depth, intrinsics),
            without hand boxes yet; None when no tracker runs.

    """

    frame: PreparedFrame
    T_raw: np.ndarray
    intrinsics: Intrinsics
    hands: tuple[HandState, ...]
    depth_ratios: np.ndarray
    depth_model: np.ndarray | None
    view: TrackingView | None


def tracking_view(frame: PreparedFrame, depth: torch.Tensor, intrinsics_model: np.ndarray
                  ) -> TrackingView:
    """Return the tracker's view of a frame: grey model input, (H, W) depth, (3, 3) K."""
    height, width = depth.shape[-2:]
    weights = torch.tensor([0.299, 0.587, 0.114], dtype=frame.pixels.dtype,
                           device=frame.pixels.device)
    gray = torch.tensordot(weights, frame.pixels, dims=1).mul(255.0).round().clamp(0, 255)
    return TrackingView(gray.to(torch.uint8).cpu().numpy(),
                        depth.detach().float().cpu().numpy(),
                        Intrinsics.from_matrix(intrinsics_model, width, height),
                        frame.mapping.content_box, np.zeros((0, 4)))


def _numpy(tensor: torch.Tensor) -> np.ndarray:
    return tensor.detach().double().cpu().numpy()


def split_frames(output: CameraSpaceOutput, frames: list[PreparedFrame], views: bool = True
                 ) -> list[CameraSpaceFrame]:
    """Return one record per frame of a B=1 block, in order (``views``: with tracker views)."""
    hands = output.hands
    frame_of_hand = output.boxes.batch_index.cpu().numpy()
    ratios = _numpy(hand_depth_ratios(output.geometry.depth.flatten(0, 1),
                                      output.boxes.batch_index, hands.joints_2d,
                                      hands.joints_cam[..., 2]))
    columns = {name: _numpy(value) for name, value in (
        ('orient', hands.mano_cam.global_orient), ('pose', hands.mano_cam.hand_pose),
        ('betas', hands.mano_cam.betas), ('transl', hands.mano_cam.transl),
        ('joints', hands.joints_cam), ('joints_2d', hands.joints_2d),
        ('boxes', output.boxes.boxes_xyxy), ('presence', output.presence))}
    sides = output.boxes.sides.cpu().numpy()
    poses = _numpy(output.T_world_cam[0])
    intrinsics = _numpy(output.intrinsics[0])
    height, width = output.geometry.depth.shape[-2:]
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
            Intrinsics.from_matrix(intrinsics[row], width, height))
        depth = None
        if frame.keyframe:
            depth = mapping.map_to_source(
                output.geometry.depth[0, row].detach().float().cpu().numpy())
        view = (tracking_view(frame, output.geometry.depth[0, row], intrinsics[row]) if views
                else None)
        records.append(CameraSpaceFrame(frame, poses[row], used, states, ratios[rows], depth,
                                        view))
    return records


def split_geometry(geometry: GeometryOutput, T_world_cam: torch.Tensor,
                   intrinsics: torch.Tensor, frames: list[PreparedFrame], views: bool = True
                   ) -> list[CameraSpaceFrame]:
    """Return one hand-less record per frame of a B=1 block (a source outside the model).

    As ``split_frames`` without the hand branch: the raw pose, the intrinsics used and, for
    keyframes, the model depth at the source size.
    """
    poses = _numpy(T_world_cam[0])
    matrices = _numpy(intrinsics[0])
    height, width = geometry.depth.shape[-2:]
    records = []
    for row, frame in enumerate(frames):
        used = frame.intrinsics or frame.mapping.intrinsics_to_source(
            Intrinsics.from_matrix(matrices[row], width, height))
        depth = None
        if frame.keyframe:
            depth = frame.mapping.map_to_source(geometry.depth[0, row].detach().float().cpu()
                                                .numpy())
        view = tracking_view(frame, geometry.depth[0, row], matrices[row]) if views else None
        records.append(CameraSpaceFrame(frame, poses[row], used, (), np.zeros(0), depth, view))
    return records


def source_depth_ratios(geometry: GeometryOutput, row: int, frame: PreparedFrame,
                        hands: tuple[HandState, ...]) -> np.ndarray:
    """Return (N,) metric-to-model depth ratios of hands found outside the model (scale)."""
    if not hands:
        return np.zeros(0)
    joints_2d = np.stack([frame.mapping.points_to_model(hand.joints_2d) for hand in hands])
    depths = np.stack([hand.joints_cam[:, 2] for hand in hands])
    depth = geometry.depth[0, row:row + 1].detach().double()
    return _numpy(hand_depth_ratios(depth, torch.zeros(len(hands), dtype=torch.long),
                                    torch.as_tensor(joints_2d, dtype=torch.float64),
                                    torch.as_tensor(depths, dtype=torch.float64)))
