"""Settings of the engine's output stage: hand identity, one shape per side, smoothing.

Each field is also a parameter of the estimator node (``identity.*``, ``shape.*``,
``smoothing.*``): its description and range live here, once.
"""

from dataclasses import dataclass
from typing import Final

from infinihand_ros.core.config import require_at_least
from infinihand_ros.core.config import require_positive
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.core.parameters import check_parameters
from infinihand_ros.core.parameters import nested
from infinihand_ros.core.parameters import parameter

SMOOTHING_MODES: Final = ('none', 'one_euro')  # not 'off': YAML reads a bare off as false


@dataclass(frozen=True)
class SmoothingConfig:
    """One-Euro smoothing of the world-frame joints (the wrist pose follows them)."""

    mode: str = parameter('none', 'Smoothing of the hand outputs (world-frame joints).',
                          choices=SMOOTHING_MODES)
    min_cutoff_hz: float = parameter(1.0, 'One-Euro minimum cutoff frequency (lower: smoother '
                                     'at rest, more lag), Hz.', 1e-6, 1000.0)
    beta: float = parameter(0.0, 'One-Euro speed coefficient (higher: less lag when moving; 0: '
                            'a fixed low-pass).', 0.0, 1000.0)
    d_cutoff_hz: float = parameter(1.0, 'One-Euro cutoff of the speed estimate (Casiez et al. '
                                   'recommend 1 Hz), Hz.', 1e-6, 1000.0)

    def __post_init__(self) -> None:
        check_parameters(self, 'smoothing.')
        require_positive('smoothing', min_cutoff_hz=self.min_cutoff_hz,
                         d_cutoff_hz=self.d_cutoff_hz)
        require_at_least('smoothing', 0.0, beta=self.beta)


@dataclass(frozen=True)
class IdentityConfig:
    """Per-side hand identity over time."""

    match_radius: float = parameter(0.25, 'A hand this close to a track (fraction of the image '
                                    'diagonal) continues it.', 1e-6, 10.0)
    max_gap_s: float = parameter(0.5, 'A hand track unseen for longer is forgotten (the '
                                 "model's side wins again), s.", 1e-6, 3600.0)

    def __post_init__(self) -> None:
        require_positive('identity', match_radius=self.match_radius,
                         max_gap_s=self.max_gap_s)


@dataclass(frozen=True)
class ShapeConfig:
    """One hand shape (MANO betas) per side over time."""

    enabled: bool = parameter(True, 'Share one hand shape (MANO betas) per side over time.')
    min_confidence: float = parameter(0.7, 'Only hands at least this confident shape the shared '
                                      'estimate.', 0.0, 1.0)
    min_samples: int = parameter(10, 'Confident hands needed before the shared shape is used.',
                                 1, 2 ** 31 - 1)

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_confidence <= 1.0:
            raise ConfigError(f'shape.min_confidence: must be in [0, 1], got '
                              f'{self.min_confidence}')
        require_at_least('shape', 1, min_samples=self.min_samples)


@dataclass(frozen=True)
class OutputConfig:
    """The engine's output stage (``engine.output``), the same for every consumer.

    Attributes:
        identity: per-side hand identity over time.
        shape: one hand shape (MANO betas) per side over time.
        smoothing: One-Euro smoothing of the world-frame joints.

    """

    identity: IdentityConfig = nested(IdentityConfig)
    shape: ShapeConfig = nested(ShapeConfig)
    smoothing: SmoothingConfig = nested(SmoothingConfig)
