"""Perspective-correct hand crops through a virtual crop camera, with left-hand flipping.

For each hand box the crop camera shares the image camera's optical centre and is rotated by
``R_h<-c`` so that its optical axis passes through the box centre (the smallest such rotation,
so a centred box gives ``R = I``). Its intrinsics ``K^h`` have square pixels, the principal point
at the crop centre ``((S - 1) / 2, (S - 1) / 2)`` and the focal length that fits the expanded
square box into the ``S x S`` crop. Crop pixel ``q`` then sees image pixel
``K R_h<-c^T K^h^-1 q`` (a homography), and a point ``X_c`` of the camera frame projects into
the crop at ``K^h R_h<-c X_c``.

Canonical crops: a left hand is shown to the network mirrored left-right, as a right hand.
Because ``K^h`` is symmetric about the crop centre, mirroring the crop image
(``u -> S - 1 - u``) is exactly mirroring the crop-camera frame (``x -> -x``, see
``mano/mirror.py``); ``canonical`` in names below means "after that flip, where it applies".

Pixel convention (OpenCV, as the synthetic renderer): pixel (column i, row j) is centred at
``(u, v) = (i, j)``. A box ``(x0, y0, x1, y1)`` has exclusive ``x1, y1`` pixel indices, so it spans
``[x0 - 0.5, x1 - 0.5]``. Normalised coordinates are grid_sample's ``align_corners=False`` ones:
``x_n = (2 u + 1) / W - 1``, -1 and 1 at the outer pixel edges.
"""

from dataclasses import dataclass

from infinihand_ros.core.errors import InputError
import torch
import torch.nn.functional as F

#: Normalised coordinate given to sample points whose ray points away from the image camera,
#: so grid_sample reads zeros there.
_OUTSIDE = -4.0
#: Smallest homogeneous depth of a crop ray in the image camera treated as "in front".
_MIN_RAY_DEPTH = 1e-6


@dataclass(frozen=True)
class CropCameras:
    """Virtual crop cameras of N hand boxes.

    Attributes:
        rotation_h_from_c: (N, 3, 3) ``R_h<-c``, image camera frame to crop-camera frame.
        intrinsics: (N, 3, 3) ``K^h`` of the (unflipped) crop, pixels.
        image_intrinsics: (N, 3, 3) K of each box's image, pixels.
        flipped: (N,) bool, the canonical crop is mirrored (left hands).
        crop_size: side S of the square crop, pixels.

    """

    rotation_h_from_c: torch.Tensor
    intrinsics: torch.Tensor
    image_intrinsics: torch.Tensor
    flipped: torch.Tensor
    crop_size: int

    def crop_to_image_homography(self) -> torch.Tensor:
        """Return (N, 3, 3) maps from canonical crop pixels to image pixels (homogeneous)."""
        flip = _flip_matrix(self.flipped, self.crop_size, self.intrinsics.dtype)
        return (self.image_intrinsics @ self.rotation_h_from_c.transpose(-1, -2)
                @ torch.linalg.inv(self.intrinsics) @ flip)


def _rotation_between(source: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Smallest rotations (N, 3, 3) taking unit vectors ``source`` to ``target`` (not opposite).

    ``R = I + [v]x + [v]x^2 / (1 + c)`` with ``v = s x t`` and ``c = s . t`` (Rodrigues).
    """
    v = torch.linalg.cross(source, target, dim=-1)
    c = (source * target).sum(-1)
    zero = torch.zeros_like(c)
    skew = torch.stack([zero, -v[:, 2], v[:, 1], v[:, 2], zero, -v[:, 0],
                        -v[:, 1], v[:, 0], zero], dim=-1).view(-1, 3, 3)
    eye = torch.eye(3, dtype=source.dtype, device=source.device).expand_as(skew)
    return eye + skew + skew @ skew / (1.0 + c)[:, None, None]


def _flip_matrix(flipped: torch.Tensor, crop_size: int, dtype: torch.dtype) -> torch.Tensor:
    """Return (N, 3, 3) pixel maps canonical crop -> crop: ``u -> S - 1 - u`` where flipped."""
    n = flipped.shape[0]
    flip = torch.eye(3, dtype=dtype, device=flipped.device).repeat(n, 1, 1)
    flip[flipped, 0, 0] = -1.0
    flip[flipped, 0, 2] = crop_size - 1.0
    return flip


def _unproject(pixels: torch.Tensor, intrinsics: torch.Tensor) -> torch.Tensor:
    """Rays (N, P, 3) with z = 1 through pixels (N, P, 2) of cameras K (N, 3, 3)."""
    homogeneous = torch.cat([pixels, torch.ones_like(pixels[..., :1])], dim=-1)
    return homogeneous @ torch.linalg.inv(intrinsics).transpose(-1, -2)


def build_crop_cameras(boxes_xyxy: torch.Tensor, image_intrinsics: torch.Tensor,
                       flipped: torch.Tensor, crop_size: int,
                       box_expansion: float) -> CropCameras:
    """Build the crop cameras of tight hand boxes.

    Args:
        boxes_xyxy: (N, 4) tight boxes (x0, y0, x1, y1) in image pixels, x1/y1 exclusive.
        image_intrinsics: (N, 3, 3) K of each box's image.
        flipped: (N,) bool, show the crop mirrored (left hands).
        crop_size: side S of the square crop, pixels.
        box_expansion: the crop covers a square of this factor times the box's longer side.

    Returns:
        The crop cameras; every corner of the expanded square lies inside the crop.

    Raises:
        InputError: for wrong shapes or an empty box.

    """
    n = boxes_xyxy.shape[0]
    if tuple(boxes_xyxy.shape) != (n, 4) or tuple(image_intrinsics.shape) != (n, 3, 3) or \
            tuple(flipped.shape) != (n,):
        raise InputError(f'crop cameras: expected boxes (N, 4), intrinsics (N, 3, 3) and flipped '
                         f'(N,), got {tuple(boxes_xyxy.shape)}, {tuple(image_intrinsics.shape)} '
                         f'and {tuple(flipped.shape)}')
    size = (boxes_xyxy[:, 2:] - boxes_xyxy[:, :2]).amax(dim=-1)
    if (size <= 0).any():
        raise InputError(f'hand boxes: {int((size <= 0).sum())} box(es) have no area; pass '
                         '(x0, y0, x1, y1) with x1 > x0 or y1 > y0')
    centre = 0.5 * (boxes_xyxy[:, :2] + boxes_xyxy[:, 2:]) - 0.5
    half = 0.5 * box_expansion * size
    signs = torch.tensor([[-1.0, -1.0], [1.0, -1.0], [-1.0, 1.0], [1.0, 1.0]],
                         dtype=boxes_xyxy.dtype, device=boxes_xyxy.device)
    points = torch.cat([centre[:, None], centre[:, None] + signs * half[:, None, None]], dim=1)
    rays = _unproject(points, image_intrinsics)
    axis = F.normalize(rays[:, 0], dim=-1)
    optical_axis = torch.zeros_like(axis)
    optical_axis[:, 2] = 1.0
    rotation = _rotation_between(axis, optical_axis)
    corners = rays[:, 1:] @ rotation.transpose(-1, -2)
    extent = (corners[..., :2] / corners[..., 2:]).abs().flatten(1).amax(dim=-1)
    focal = 0.5 * crop_size / extent
    intrinsics = torch.zeros_like(image_intrinsics)
    intrinsics[:, 0, 0] = focal
    intrinsics[:, 1, 1] = focal
    intrinsics[:, :2, 2] = 0.5 * (crop_size - 1.0)
    intrinsics[:, 2, 2] = 1.0
    return CropCameras(rotation, intrinsics, image_intrinsics, flipped.bool(), crop_size)


def apply_homography(homography: torch.Tensor, pixels: torch.Tensor) -> torch.Tensor:
    """Map pixels (N, P, 2) through homographies (N, 3, 3); points with w <= 0 go far outside.

    Returns:
        (N, P, 2) mapped pixels; a point whose ray points away from the camera is put at a large
        negative coordinate so samplers read zeros there.

    """
    homogeneous = torch.cat([pixels, torch.ones_like(pixels[..., :1])], dim=-1)
    mapped = homogeneous @ homography.transpose(-1, -2)
    w = mapped[..., 2:]
    in_front = w > _MIN_RAY_DEPTH
    safe_w = torch.where(in_front, w, torch.ones_like(w))
    return torch.where(in_front, mapped[..., :2] / safe_w, torch.full_like(mapped[..., :2], -1e6))


def pixels_to_normalized(pixels: torch.Tensor, width: int, height: int) -> torch.Tensor:
    """Convert pixels (..., 2) to grid_sample coordinates (``align_corners=False``)."""
    size = torch.tensor([width, height], dtype=pixels.dtype, device=pixels.device)
    return (2.0 * pixels + 1.0) / size - 1.0


def normalized_to_pixels(normalized: torch.Tensor, width: int, height: int) -> torch.Tensor:
    """Convert grid_sample coordinates (..., 2) (``align_corners=False``) to pixels."""
    size = torch.tensor([width, height], dtype=normalized.dtype, device=normalized.device)
    return ((normalized + 1.0) * size - 1.0) / 2.0


def flip_normalized(points: torch.Tensor, flipped: torch.Tensor) -> torch.Tensor:
    """Mirror normalised crop points (N, J, 2) left-right (``x -> -x``) where ``flipped`` (N,).

    Its own inverse: maps canonical crop coordinates to crop coordinates and back.
    """
    sign = torch.where(flipped, -1.0, 1.0).to(points.dtype)
    return torch.stack([points[..., 0] * sign[:, None], points[..., 1]], dim=-1)


def crop_pixel_grid(crop_size: int, dtype: torch.dtype, device: torch.device) -> torch.Tensor:
    """Return the (S * S, 2) pixel centres (u, v) of an S x S crop, row-major."""
    coords = torch.arange(crop_size, dtype=dtype, device=device)
    v, u = torch.meshgrid(coords, coords, indexing='ij')
    return torch.stack([u.flatten(), v.flatten()], dim=-1)


def sample_at_crop_pixels(maps: torch.Tensor, batch_index: torch.Tensor, cameras: CropCameras,
                          crop_pixels: torch.Tensor, image_size: tuple[int, int]) -> torch.Tensor:
    """Bilinearly sample image-aligned maps at canonical crop pixels of each box.

    Args:
        maps: (B, C, Hm, Wm) maps covering the whole (H, W) image (an image, or patch features
            whose cells tile it exactly).
        batch_index: (N,) long, the image of each box.
        cameras: the N crop cameras.
        crop_pixels: (P, 2) canonical crop pixels (u, v) sampled for every box.
        image_size: (H, W) of the image the intrinsics refer to, pixels.

    Returns:
        (N, C, P) samples; zero outside the image.

    """
    height, width = image_size
    pixels = crop_pixels.to(cameras.intrinsics.dtype).expand(batch_index.shape[0], -1, -1)
    image_pixels = apply_homography(cameras.crop_to_image_homography(), pixels)
    grid = pixels_to_normalized(image_pixels, width, height).clamp(_OUTSIDE, -_OUTSIDE)
    samples = F.grid_sample(maps[batch_index], grid[:, None].to(maps.dtype), mode='bilinear',
                            padding_mode='zeros', align_corners=False)
    return samples[:, :, 0]


def warp_to_crop(images: torch.Tensor, batch_index: torch.Tensor,
                 cameras: CropCameras) -> torch.Tensor:
    """Render the canonical S x S crops of N boxes from their images.

    Args:
        images: (B, C, H, W) images (any value range) whose intrinsics the cameras use.
        batch_index: (N,) long, the image of each box.
        cameras: the N crop cameras.

    Returns:
        (N, C, S, S) canonical crops (left hands mirrored); zero outside the image.

    """
    size = cameras.crop_size
    grid = crop_pixel_grid(size, cameras.intrinsics.dtype, images.device)
    samples = sample_at_crop_pixels(images, batch_index, cameras, grid, tuple(images.shape[-2:]))
    return samples.view(samples.shape[0], samples.shape[1], size, size)
