"""Pycolmap (COLMAP/Ceres) bundle adjustment of a ``BAProblem``: the test oracle."""

from types import ModuleType

from infinihand_ros.ba.problem import BAProblem
from infinihand_ros.core import geometry
import numpy as np

CAMERA_ID = 1


def _add_images(pycolmap: ModuleType, reconstruction, problem: BAProblem) -> list[list[int]]:
    """Add one image per keyframe holding its host and observed pixels; return track per point."""
    frames = np.r_[problem.host, problem.obs_frame]
    tracks = np.r_[np.arange(len(problem.host)), problem.obs_track]
    pixels = np.r_[problem.host_xy, problem.obs_xy]
    world_to_cam = geometry.invert_transform(problem.T_world_cam)
    tracks_per_image = []
    for frame in range(problem.num_frames):
        mine = np.flatnonzero(frames == frame)
        points = pycolmap.Point2DList([pycolmap.Point2D(pixels[i]) for i in mine])
        image = pycolmap.Image(name=str(frame), points2D=points, camera_id=CAMERA_ID,
                               image_id=frame + 1)
        reconstruction.add_image_with_trivial_frame(
            image, pycolmap.Rigid3d(world_to_cam[frame, :3, :]))
        tracks_per_image.append(tracks[mine].tolist())
    return tracks_per_image


def colmap_bundle_adjust(pycolmap: ModuleType, problem: BAProblem, k: np.ndarray,
                         refine_lens: bool = False
                         ) -> np.ndarray | tuple[np.ndarray, float, float]:
    """Run pycolmap's BA (fixed poses as in ``problem``).

    Without ``refine_lens`` the intrinsics ``k`` are held (a PINHOLE camera). With it, one
    SIMPLE_RADIAL camera (focal ``k[0, 0]``, k1 0 to start) is refined with the poses.

    Returns:
        (F, 4, 4) refined camera-to-world poses; with ``refine_lens`` also the refined focal
        length (px) and k1.

    """
    reconstruction = pycolmap.Reconstruction()
    width, height = int(2 * k[0, 2]), int(2 * k[1, 2])
    camera = (pycolmap.Camera(model='SIMPLE_RADIAL', width=width, height=height,
                              camera_id=CAMERA_ID, params=[k[0, 0], k[0, 2], k[1, 2], 0.0])
              if refine_lens else
              pycolmap.Camera(model='PINHOLE', width=width, height=height, camera_id=CAMERA_ID,
                              params=[k[0, 0], k[1, 1], k[0, 2], k[1, 2]]))
    reconstruction.add_camera_with_trivial_rig(camera)
    tracks_per_image = _add_images(pycolmap, reconstruction, problem)
    elements = [[] for _ in problem.host]
    for frame, tracks in enumerate(tracks_per_image):
        for index, track in enumerate(tracks):
            elements[track].append(pycolmap.TrackElement(frame + 1, index))
    rays = np.c_[(problem.host_xy - k[:2, 2]) / np.diag(k)[:2], np.ones(len(problem.host))]
    points = geometry.transform_points(problem.T_world_cam[problem.host],
                                       (rays / problem.inv_depth[:, None])[:, None])[:, 0]
    for point, track in zip(points, elements):
        reconstruction.add_point3D(point, pycolmap.Track(track))
    config = pycolmap.BundleAdjustmentConfig()
    for frame in range(problem.num_frames):
        config.add_image(frame + 1)
    if not refine_lens:
        config.set_constant_cam_intrinsics(CAMERA_ID)
    for frame in np.flatnonzero(problem.fixed):
        config.set_constant_rig_from_world_pose(int(frame + 1))
    options = pycolmap.BundleAdjustmentOptions()
    options.refine_focal_length = refine_lens
    options.refine_principal_point = False
    options.refine_extra_params = refine_lens
    solver = options.ceres.solver_options
    solver.function_tolerance = solver.gradient_tolerance = solver.parameter_tolerance = 1e-15
    solver.max_num_iterations = 200
    pycolmap.create_default_bundle_adjuster(options, config, reconstruction).solve()
    world_to_cam = np.stack([
        np.r_[reconstruction.image(frame + 1).cam_from_world().matrix(), [[0.0, 0.0, 0.0, 1.0]]]
        for frame in range(problem.num_frames)])
    poses = geometry.invert_transform(world_to_cam)
    if not refine_lens:
        return poses
    focal, _, _, k1 = reconstruction.camera(CAMERA_ID).params
    return poses, float(focal), float(k1)
