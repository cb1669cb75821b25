"""Real MANO as a differentiable layer: linear blend skinning over user-supplied MANO arrays.

Same parameters and outputs as the built-in skeleton. Poses are relative to the flat hand, like
smplx's ``MANOLayer`` used by HaMeR / WiLoR / HaWoR: ``hands_mean`` is not added (subtract it
from a pose meant for ``flat_hand_mean=False`` consumers). Steps, for a batch of B hands:

1. shape: ``v_shaped = v_template + shapedirs . betas``; joints ``J = J_regressor v_shaped``;
2. pose blend: ``v_posed = v_shaped + posedirs . vec(R_i - I)`` over MANO joints 1-15;
3. forward kinematics along MANO's tree (``kinematics.py``) with rest offsets from ``J``;
4. skinning: each vertex moves by the weight-blended joint transforms
   ``A_i = [G_i | p_i - G_i J_i]``; then ``transl`` is added.

So the wrist is at ``J0(betas) + transl`` and ``global_orient`` rotates the hand about ``J0``.
The 21 joints are the 16 posed joints plus the fingertip vertices ``MANO_TIP_VERTEX_IDS``, in
OpenPose order.
"""

from infinihand_ros.core.hand_conventions import MANO_TIP_VERTEX_IDS
from infinihand_ros.core.hand_conventions import MANO_TO_OPENPOSE
from infinihand_ros.mano.base import HandModel
from infinihand_ros.mano.base import HandModelOutput
from infinihand_ros.mano.kinematics import forward_kinematics
from infinihand_ros.mano.kinematics import offsets_from_positions
from infinihand_ros.mano.mano_file import ManoData
from infinihand_ros.mano.mano_file import NUM_POSE_FEATURES
import roma
import torch


class ManoHandModel(HandModel):
    """MANO linear blend skinning for one side (the side of the data it is built from).

    Computation runs in the dtype and device of the module's buffers (the constructor's ``dtype``,
    or torch's default; ``.to(device)`` works like for any module).
    """

    def __init__(self, data: ManoData, dtype: torch.dtype | None = None) -> None:
        """Build the layer from validated MANO arrays (see ``mano_file.load_mano_data``).

        Args:
            data: the model arrays; the layer's side is ``data.side``.
            dtype: dtype of the buffers (default: torch's default dtype).

        """
        super().__init__(data.side)
        dtype = dtype or torch.get_default_dtype()

        def tensor(array: object) -> torch.Tensor:
            return torch.as_tensor(array, dtype=dtype)

        vertex_count = data.v_template.shape[0]
        regressor = tensor(data.joint_regressor)
        self.register_buffer('v_template', tensor(data.v_template))
        self.register_buffer('shapedirs', tensor(data.shapedirs))
        self.register_buffer('posedirs', tensor(
            data.posedirs.reshape(vertex_count * 3, NUM_POSE_FEATURES).T))
        self.register_buffer('joint_regressor', regressor)
        self.register_buffer('weights', tensor(data.weights))
        self.register_buffer('joint_template', regressor @ tensor(data.v_template))
        self.register_buffer('joint_shapedirs',
                             torch.einsum('jv,vcl->jcl', regressor, tensor(data.shapedirs)))
        self.register_buffer('faces', torch.as_tensor(data.faces, dtype=torch.long),
                             persistent=False)
        self.register_buffer('tip_vertex_ids',
                             torch.as_tensor(MANO_TIP_VERTEX_IDS, dtype=torch.long),
                             persistent=False)
        self.register_buffer('to_openpose', torch.as_tensor(MANO_TO_OPENPOSE, dtype=torch.long),
                             persistent=False)

    def rest_joints(self, betas: torch.Tensor) -> torch.Tensor:
        """Regressed rest joints (B, 16, 3) in metres for shape coefficients ``betas`` (B, 10)."""
        return self.joint_template + torch.einsum('bl,jcl->bjc', betas, self.joint_shapedirs)

    def _forward_checked(self, global_orient: torch.Tensor, hand_pose: torch.Tensor,
                         betas: torch.Tensor, transl: torch.Tensor) -> HandModelOutput:
        batch = global_orient.shape[0]
        local_rotations = roma.rotvec_to_rotmat(torch.cat([global_orient[:, None], hand_pose], 1))
        v_shaped = self.v_template + torch.einsum('bl,vcl->bvc', betas, self.shapedirs)
        rest_joints = self.rest_joints(betas)
        identity = torch.eye(3, dtype=local_rotations.dtype, device=local_rotations.device)
        pose_features = (local_rotations[:, 1:] - identity).reshape(batch, NUM_POSE_FEATURES)
        v_posed = v_shaped + (pose_features @ self.posedirs).view_as(v_shaped)
        global_rotations, joints = forward_kinematics(
            local_rotations, offsets_from_positions(rest_joints))
        vertices = self._skin(v_posed, global_rotations, joints, rest_joints) + transl[:, None]
        joints = joints + transl[:, None]
        with_tips = torch.cat([joints, vertices[:, self.tip_vertex_ids]], dim=1)
        return HandModelOutput(joints=with_tips[:, self.to_openpose],
                               global_rotations=global_rotations, vertices=vertices)

    def _skin(self, v_posed: torch.Tensor, global_rotations: torch.Tensor,
              joints: torch.Tensor, rest_joints: torch.Tensor) -> torch.Tensor:
        """Linear blend skinning of (B, V, 3) posed rest vertices with the joint transforms."""
        translations = joints - torch.einsum('bjrc,bjc->bjr', global_rotations, rest_joints)
        blended_rotations = torch.einsum('vj,bjrc->bvrc', self.weights, global_rotations)
        blended_translations = torch.einsum('vj,bjr->bvr', self.weights, translations)
        return torch.einsum('bvrc,bvc->bvr', blended_rotations, v_posed) + blended_translations
