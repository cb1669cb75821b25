"""Weights and constants of the training losses (``config/train_losses.yaml``, section ``losses``).

The paper (Sec. 3.2-3.3, appendix B) names every weight but states no value; the defaults below
are placeholders (1.0 for every weight) until training tunes them, and the few numerical
constants it leaves open (the smooth-L1 width, the arccos clamp, the normalisation floor) are
ours. Each config refuses NaN, infinite or negative weights and non-positive constants at
construction, so at load, naming the key (e.g. ``losses.camera.rel_translation_weight``).
"""

import dataclasses
from dataclasses import dataclass
from dataclasses import field
from pathlib import Path
from typing import Final

from infinihand_ros.core.config import config_dir
from infinihand_ros.core.config import load_config
from infinihand_ros.core.config import require_at_least
from infinihand_ros.core.config import require_finite
from infinihand_ros.core.config import require_positive
from infinihand_ros.core.errors import ConfigError

#: Top-level section of ``config/train_losses.yaml`` holding the ``LossConfig`` fields.
LOSSES_SECTION: Final = 'losses'
#: The package's loss configuration file.
LOSSES_FILE: Final = 'train_losses.yaml'


def _require_weights(owner: str, config: object) -> None:
    """Raise ConfigError naming the first float field of ``config`` not finite and >= 0."""
    values = {item.name: getattr(config, item.name) for item in dataclasses.fields(config)
              if isinstance(getattr(config, item.name), float)}
    require_finite(owner, **values)
    require_at_least(owner, 0.0, **values)


@dataclass(frozen=True)
class MaskLossConfig:
    """Mask loss ``L_mask = lambda_BCE L_BCE + lambda_Dice L_Dice`` (Sec. 3.2, appendix B.1).

    Attributes:
        bce_weight: lambda_BCE.
        dice_weight: lambda_Dice.

    """

    bce_weight: float = 1.0
    dice_weight: float = 1.0

    def __post_init__(self) -> None:
        """Refuse values that make the loss meaningless (raises ConfigError)."""
        _require_weights(f'{LOSSES_SECTION}.mask', self)


@dataclass(frozen=True)
class LandmarkLossConfig:
    """2D landmark loss ``lambda_2D L_2D`` (appendix B.1).

    Attributes:
        weight: lambda_2D, the weight of L_2D in L_joint (Sec. 3.3).
        max_abs: targets with |x| or |y| above this (normalised crop coordinates, 1 = the crop's
            outer pixel edge) are out of range and leave the valid set.

    """

    weight: float = 1.0
    max_abs: float = 1.0

    def __post_init__(self) -> None:
        """Refuse values that make the loss meaningless (raises ConfigError)."""
        _require_weights(f'{LOSSES_SECTION}.landmarks', self)
        require_positive(f'{LOSSES_SECTION}.landmarks', max_abs=self.max_abs)


@dataclass(frozen=True)
class ManoLossConfig:
    """Camera-space MANO loss weights (Sec. 3.2; appendix B.2).

    Attributes:
        orient_weight: lambda_g (global orientation).
        pose_weight: lambda_theta (15 local joint rotations).
        shape_weight: lambda_beta.
        trans_weight: lambda_t (camera-frame translation).
        joints_weight: lambda_J (camera-frame 3D joints).
        reproj_weight: lambda_r (reprojection).
        min_depth_m: predicted joint depths are floored at this before projecting (m), as the
            EPE metric of appendix A does, so a joint behind the camera keeps a finite gradient.

    """

    orient_weight: float = 1.0
    pose_weight: float = 1.0
    shape_weight: float = 1.0
    trans_weight: float = 1.0
    joints_weight: float = 1.0
    reproj_weight: float = 1.0
    min_depth_m: float = 0.01

    def __post_init__(self) -> None:
        """Refuse values that make the loss meaningless (raises ConfigError)."""
        _require_weights(f'{LOSSES_SECTION}.mano', self)
        require_positive(f'{LOSSES_SECTION}.mano', min_depth_m=self.min_depth_m)


@dataclass(frozen=True)
class WorldJointLossConfig:
    """World-space joint loss ``lambda_w L_joints^w`` (appendix B.3).

    Attributes:
        weight: lambda_w.
        epsilon: width of the smooth-L1 penalty rho_eps, in kappa-normalised units.

    """

    weight: float = 1.0
    epsilon: float = 0.02

    def __post_init__(self) -> None:
        """Refuse values that make the loss meaningless (raises ConfigError)."""
        _require_weights(f'{LOSSES_SECTION}.world_joints', self)
        require_positive(f'{LOSSES_SECTION}.world_joints', epsilon=self.epsilon)


@dataclass(frozen=True)
class CameraLossConfig:
    """Camera loss ``lambda_cam (alpha_abs L_abs-pose + alpha_rel L_rel-pose)`` (appendix B.3).

    Attributes:
        weight: lambda_cam.
        abs_weight: alpha_abs.
        rel_weight: alpha_rel.
        rel_translation_weight: lambda_rel,u, weight of the relative translation L1.
        epsilon: width of rho_eps in the absolute-pose term (normalised translation units,
            quaternion units and radians alike, as the paper uses one rho_eps for all nine).

    """

    weight: float = 1.0
    abs_weight: float = 1.0
    rel_weight: float = 1.0
    rel_translation_weight: float = 1.0
    epsilon: float = 0.02

    def __post_init__(self) -> None:
        """Refuse values that make the loss meaningless (raises ConfigError)."""
        _require_weights(f'{LOSSES_SECTION}.camera', self)
        require_positive(f'{LOSSES_SECTION}.camera', epsilon=self.epsilon)


@dataclass(frozen=True)
class TemporalLossConfig:
    """Temporal consistency ``lambda_temp L_temp`` (Sec. 3.3; the paper gives no formula).

    Attributes:
        weight: lambda_temp.
        camera_weight: weight of the camera part inside L_temp.
        mano_weight: weight of the MANO part.
        mask_weight: weight of the mask part.
        landmarks_weight: weight of the 2D landmark part.

    """

    weight: float = 1.0
    camera_weight: float = 1.0
    mano_weight: float = 1.0
    mask_weight: float = 1.0
    landmarks_weight: float = 1.0

    def __post_init__(self) -> None:
        """Refuse values that make the loss meaningless (raises ConfigError)."""
        _require_weights(f'{LOSSES_SECTION}.temporal', self)


@dataclass(frozen=True)
class DepthLossConfig:
    """Depth loss ``lambda_depth L_depth`` (ours: the tiny model has no pretrained depth).

    Attributes:
        weight: lambda_depth.
        confidence_alpha: alpha of the ``- alpha log c`` confidence term (VGGT's form).

    """

    weight: float = 1.0
    confidence_alpha: float = 0.2

    def __post_init__(self) -> None:
        """Refuse values that make the loss meaningless (raises ConfigError)."""
        _require_weights(f'{LOSSES_SECTION}.depth', self)


@dataclass(frozen=True)
class LossConfig:
    """Every loss weight and constant (``config/train_losses.yaml``, section ``losses``).

    Attributes:
        mask: L_mask.
        landmarks: L_2D.
        mano: L_MANO.
        world_joints: L_joints^w.
        camera: L_camera.
        temporal: L_temp.
        depth: L_depth (ours, for models without pretrained depth).
        rotation_clamp_eps: epsilon of d_SO(3): the arccos argument is clamped to
            [-1 + eps, 1 - eps], so d(R, R) = arccos(1 - eps) ~ sqrt(2 eps) (a constant floor
            with zero gradient) and the gradient stays finite at 0 and pi.
        min_scale_m: floor of the sample-level normalisation scale kappa (m).

    """

    mask: MaskLossConfig = field(default_factory=MaskLossConfig)
    landmarks: LandmarkLossConfig = field(default_factory=LandmarkLossConfig)
    mano: ManoLossConfig = field(default_factory=ManoLossConfig)
    world_joints: WorldJointLossConfig = field(default_factory=WorldJointLossConfig)
    camera: CameraLossConfig = field(default_factory=CameraLossConfig)
    temporal: TemporalLossConfig = field(default_factory=TemporalLossConfig)
    depth: DepthLossConfig = field(default_factory=DepthLossConfig)
    rotation_clamp_eps: float = 1.0e-6
    min_scale_m: float = 0.1

    def __post_init__(self) -> None:
        """Refuse values that make the loss meaningless (raises ConfigError)."""
        require_positive(LOSSES_SECTION, rotation_clamp_eps=self.rotation_clamp_eps,
                         min_scale_m=self.min_scale_m)
        require_finite(LOSSES_SECTION, min_scale_m=self.min_scale_m)
        if not self.rotation_clamp_eps < 1.0:
            raise ConfigError(f'{LOSSES_SECTION}.rotation_clamp_eps: must be below 1 (the '
                              f'arccos argument is clamped to [-1 + eps, 1 - eps]), got '
                              f'{self.rotation_clamp_eps!r}')


def load_loss_config(path: str | Path | None = None) -> LossConfig:
    """Load the ``losses`` section of ``path`` (default: the package's train_losses.yaml).

    Raises:
        ConfigError: for a missing file or section, an unknown key or a rejected value.

    """
    return load_config(config_dir() / LOSSES_FILE if path is None else path, LOSSES_SECTION,
                       LossConfig)
