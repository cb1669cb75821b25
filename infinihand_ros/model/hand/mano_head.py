"""MANO head: fused crop features -> pose, shape, orientation and log-depth (paper H_MANO).

The head reads the fused map Z through a 1x1 readout and an MLP over the flattened grid, and
predicts residuals on the appearance encoder's coarse hand: 16 6D rotations (the orientation
Phi^h first, then the 15 joints Theta), 10 betas, and the log-depth ``l_z`` of the wrist in the
crop-camera frame as a residual on a depth prior (``t_z = exp(l_z)``). Rotations are decoded by
Gram-Schmidt (``roma.special_gramschmidt``) and returned as axis-angle. Everything is in the
canonical (right-hand) frame of the crop; the hand branch un-flips left hands.
"""

from dataclasses import dataclass
from typing import Final

from infinihand_ros.core.hand_conventions import NUM_BETAS
from infinihand_ros.model.hand.appearance_vit import NUM_POSE_TOKENS
from infinihand_ros.model.hand.appearance_vit import ROTATION_6D
from infinihand_ros.model.hand.config import HandBranchConfig
import roma
import torch
from torch import nn
import torch.nn.functional as F

#: Outputs of the final layer: 6D pose residuals, betas residuals, log-depth residual.
_NUM_POSE: Final = NUM_POSE_TOKENS * ROTATION_6D
_NUM_OUTPUTS: Final = _NUM_POSE + NUM_BETAS + 1
#: Gain of the final layer's Xavier initialisation, so the head starts at the coarse hand.
_OUTPUT_GAIN: Final = 0.01


@dataclass(frozen=True)
class ManoPrediction:
    """MANO head output for N canonical crops.

    Attributes:
        global_orient: (N, 3) axis-angle Phi^h in the canonical crop-camera frame, radians.
        hand_pose: (N, 15, 3) axis-angle Theta per joint, relative to the flat hand.
        betas: (N, 10) shape.
        log_depth: (N,) ``l_z``, log of the wrist depth t_z in metres.

    """

    global_orient: torch.Tensor
    hand_pose: torch.Tensor
    betas: torch.Tensor
    log_depth: torch.Tensor


def rotation_6d_to_matrix(rotation_6d: torch.Tensor) -> torch.Tensor:
    """Convert 6D rotations (..., 6) laid out ``[col1(3), col2(3)]`` to matrices (..., 3, 3)."""
    columns = rotation_6d.unflatten(-1, (2, 3)).transpose(-1, -2)
    return roma.special_gramschmidt(columns)


class GridReadout(nn.Module):
    """1x1 reduction of a feature grid, flattened, then a two-layer GELU MLP."""

    def __init__(self, config: HandBranchConfig, extra_inputs: int = 0) -> None:
        """Build the readout for Z (``fusion_dim`` channels on the appearance grid).

        Args:
            config: hand-branch configuration.
            extra_inputs: width of a vector concatenated to the flattened grid.

        """
        super().__init__()
        grid_h, grid_w = config.appearance.grid_size
        self.reduce = nn.Conv2d(config.fusion_dim, config.readout_channels, kernel_size=1)
        width = config.readout_channels * grid_h * grid_w + extra_inputs
        self.fc1 = nn.Linear(width, config.head_hidden_dim)
        self.fc2 = nn.Linear(config.head_hidden_dim, config.head_hidden_dim)

    def forward(self, fused: torch.Tensor, extra: torch.Tensor | None = None) -> torch.Tensor:
        """Return (N, head_hidden_dim) from Z (N, D, Gh, Gw) and an optional (N, E) vector."""
        flat = F.gelu(self.reduce(fused)).flatten(1)
        if extra is not None:
            flat = torch.cat([flat, extra], dim=1)
        return F.gelu(self.fc2(F.gelu(self.fc1(flat))))


class ManoHead(nn.Module):
    """Regress the canonical-frame MANO hand and log-depth from Z."""

    def __init__(self, config: HandBranchConfig) -> None:
        """Build the readout and the output layer (near zero: the coarse hand at start)."""
        super().__init__()
        self.readout = GridReadout(config, extra_inputs=_NUM_POSE + NUM_BETAS)
        self.output = nn.Linear(config.head_hidden_dim, _NUM_OUTPUTS)
        nn.init.xavier_uniform_(self.output.weight, gain=_OUTPUT_GAIN)
        nn.init.zeros_(self.output.bias)

    def forward(self, fused: torch.Tensor, coarse_pose_6d: torch.Tensor,
                coarse_betas: torch.Tensor, log_depth_prior: torch.Tensor) -> ManoPrediction:
        """Predict the hand.

        Args:
            fused: (N, fusion_dim, Gh, Gw) fused features Z.
            coarse_pose_6d: (N, 16, 6) coarse 6D rotations of the appearance encoder.
            coarse_betas: (N, 10) coarse shape.
            log_depth_prior: (N,) prior of ``l_z`` (log metres).

        """
        coarse = torch.cat([coarse_pose_6d.flatten(1), coarse_betas], dim=1)
        out = self.output(self.readout(fused, coarse))
        pose_6d = coarse_pose_6d + out[:, :_NUM_POSE].view_as(coarse_pose_6d)
        axis_angle = roma.rotmat_to_rotvec(rotation_6d_to_matrix(pose_6d))
        return ManoPrediction(
            global_orient=axis_angle[:, 0], hand_pose=axis_angle[:, 1:],
            betas=coarse_betas + out[:, _NUM_POSE:_NUM_POSE + NUM_BETAS],
            log_depth=log_depth_prior + out[:, -1])
