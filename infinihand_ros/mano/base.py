"""The hand-model interface: output dataclass, abstract module and input checks.

Every hand model (the built-in skeleton, real MANO) maps MANO parameters to 21 joints in the frame
of the parameters. Inputs are checked here once, so each model only implements the math.
"""

import abc
from dataclasses import dataclass

from infinihand_ros.core.errors import InputError
from infinihand_ros.core.hand_conventions import NUM_BETAS
from infinihand_ros.core.hand_conventions import NUM_HAND_POSE_JOINTS
from infinihand_ros.core.hand_conventions import side_name
import torch


@dataclass(frozen=True)
class HandModelOutput:
    """Result of a hand model's forward pass.

    Attributes:
        joints: (B, 21, 3) joints in metres, OpenPose order, in the frame of the parameters.
        global_rotations: (B, 16, 3, 3) world rotation of each MANO joint (MANO order).
        vertices: (B, V, 3) mesh vertices in metres for real MANO; None for the built-in skeleton.

    """

    joints: torch.Tensor
    global_rotations: torch.Tensor
    vertices: torch.Tensor | None


def _as_tensor(value: object, name: str, like: torch.Tensor) -> torch.Tensor:
    """Return ``value`` as a tensor of ``like``'s dtype and device (keeping gradients)."""
    if isinstance(value, torch.Tensor):
        if not value.is_floating_point():
            raise InputError(f'{name}: expected a floating-point tensor, got {value.dtype}; '
                             'convert it with .float()')
        return value.to(dtype=like.dtype, device=like.device)
    try:
        return torch.as_tensor(value, dtype=like.dtype, device=like.device)
    except (TypeError, ValueError, RuntimeError) as exc:
        raise InputError(f'{name}: cannot convert {type(value).__name__} to a tensor ({exc})'
                         ) from exc


def _check_shape(tensor: torch.Tensor, name: str, expected: tuple[int, ...],
                 hint: str = '') -> None:
    """Raise InputError unless ``tensor`` has exactly the ``expected`` shape."""
    if tuple(tensor.shape) != expected:
        batch_text = f' with B = {expected[0]} (the batch size of global_orient)'
        raise InputError(f'{name}: expected shape (B, {", ".join(map(str, expected[1:]))})'
                         f'{batch_text}, got {tuple(tensor.shape)}{hint}')


def check_hand_inputs(global_orient: object, hand_pose: object, betas: object, transl: object,
                      like: torch.Tensor) -> tuple[torch.Tensor, ...]:
    """Validate and convert the four MANO parameter inputs.

    Args:
        global_orient: (B, 3) axis-angle, radians.
        hand_pose: (B, 15, 3) axis-angle per joint relative to the flat hand (MANO joints 1-15).
        betas: (B, 10) shape coefficients.
        transl: (B, 3) translation, metres.
        like: tensor whose dtype and device the results take.

    Returns:
        The four inputs as tensors of ``like``'s dtype and device.

    Raises:
        InputError: naming the input and the shape found when a shape is wrong.

    """
    orient = _as_tensor(global_orient, 'global_orient', like)
    if orient.ndim != 2 or orient.shape[1] != 3:
        raise InputError(f'global_orient: expected shape (B, 3), got {tuple(orient.shape)}; '
                         'add a batch axis with [None] for a single hand')
    batch = orient.shape[0]
    pose = _as_tensor(hand_pose, 'hand_pose', like)
    pose_hint = ''
    if tuple(pose.shape) == (batch, NUM_HAND_POSE_JOINTS * 3):
        pose_hint = f'; reshape it with .view({batch}, {NUM_HAND_POSE_JOINTS}, 3)'
    _check_shape(pose, 'hand_pose', (batch, NUM_HAND_POSE_JOINTS, 3), pose_hint)
    shape = _as_tensor(betas, 'betas', like)
    _check_shape(shape, 'betas', (batch, NUM_BETAS))
    offset = _as_tensor(transl, 'transl', like)
    _check_shape(offset, 'transl', (batch, 3))
    return orient, pose, shape, offset


class HandModel(torch.nn.Module, abc.ABC):
    """Abstract hand model: MANO parameters in, 21 joints (and maybe vertices) out.

    Subclasses register at least one floating-point buffer (it sets the dtype and device the
    inputs are converted to) and implement ``_forward_checked``.

    Attributes:
        side: 0 for a left hand, 1 for a right hand.

    """

    def __init__(self, side: int) -> None:
        """Set the side (0 left, 1 right); ValueError for any other value."""
        super().__init__()
        side_name(side)
        self.side = side

    def forward(self, global_orient: torch.Tensor, hand_pose: torch.Tensor,
                betas: torch.Tensor, transl: torch.Tensor) -> HandModelOutput:
        """Pose the hand.

        Args:
            global_orient: (B, 3) axis-angle of the wrist, radians.
            hand_pose: (B, 15, 3) axis-angle of MANO joints 1-15 relative to the flat hand.
            betas: (B, 10) shape coefficients (0 = mean hand).
            transl: (B, 3) translation, metres.

        Returns:
            HandModelOutput in the frame of the parameters.

        Raises:
            InputError: for a wrong shape or a non-floating input.

        """
        reference = next(self.buffers())
        inputs = check_hand_inputs(global_orient, hand_pose, betas, transl, reference)
        return self._forward_checked(*inputs)

    @abc.abstractmethod
    def _forward_checked(self, global_orient: torch.Tensor, hand_pose: torch.Tensor,
                         betas: torch.Tensor, transl: torch.Tensor) -> HandModelOutput:
        """Pose the hand from inputs already checked and converted."""
