"""The hand branch of InfiniHand (paper Sec. 3.2): crops, encoders, heads, LSP and frames.

Modules: ``config`` (sizes), ``crop_camera`` (virtual crop cameras, warps, flips),
``appearance_vit`` (WiLoR-named ViT), ``adapter`` (geometric adapter), ``mano_head`` and
``landmark_head``, ``lsp`` (eq. 5), ``frames`` (eqs. 6 and 9) and ``hand_branch`` (``HandBranch``).
"""
