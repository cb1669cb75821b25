"""2D landmark head (paper H_2D): 21 landmarks in normalised canonical crop coordinates.

Coordinates follow grid_sample's ``align_corners=False`` convention over the square crop
(-1 and 1 at the outer pixel edges, x right, y down), OpenPose joint order, in the canonical
(mirrored for left hands) crop, as the paper's L_2D compares them. The head also returns a
per-box confidence in [0, 1] (a hand-presence score; the paper's losses do not define one, so
its training target is left to the training code).
"""

from typing import Final

from infinihand_ros.core.hand_conventions import NUM_JOINTS
from infinihand_ros.model.hand.config import HandBranchConfig
from infinihand_ros.model.hand.mano_head import GridReadout
import torch
from torch import nn

#: Outputs: (x, y) per landmark, then one confidence logit.
_NUM_OUTPUTS: Final = 2 * NUM_JOINTS + 1


class LandmarkHead(nn.Module):
    """Regress 21 normalised crop landmarks and a confidence from Z."""

    def __init__(self, config: HandBranchConfig) -> None:
        """Build the readout and the output layer."""
        super().__init__()
        self.readout = GridReadout(config)
        self.output = nn.Linear(config.head_hidden_dim, _NUM_OUTPUTS)

    def forward(self, fused: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Return landmarks (N, 21, 2) and confidence (N,) from Z (N, D, Gh, Gw)."""
        out = self.output(self.readout(fused))
        return out[:, :-1].view(out.shape[0], NUM_JOINTS, 2), torch.sigmoid(out[:, -1])
