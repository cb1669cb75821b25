"""What made a dataset's episodes: hand source, model weights, engine settings, package version.

Each episode's record (``meta/infinihand_conversion.json``) and the dataset card carry it, so a
dataset that mixes runs says which frames came from which model. Weights are identified by name
and the SHA-256 of their files; the engine settings by the SHA-256 of their resolved form.
"""

from dataclasses import asdict
from dataclasses import dataclass
import hashlib
import importlib.metadata
import json
from pathlib import Path
from typing import Any, Final

from infinihand_ros.core.config import config_to_dict
from infinihand_ros.engine.config import EngineConfig
from infinihand_ros.model.io.bundled import resolve_checkpoint

PACKAGE: Final = 'infinihand_ros'
#: The hand source of engines that predate ``EngineConfig.hands`` (the paper's hand branch).
DEFAULT_HAND_SOURCE: Final = 'infinihand'
#: Weight files hashed in a checkpoint directory.
WEIGHT_SUFFIXES: Final = ('.safetensors', '.pt', '.pth', '.bin')
_CHUNK_BYTES: Final = 1 << 20


@dataclass(frozen=True)
class Provenance:
    """What converted an episode.

    Attributes:
        hand_source: where the hands came from ('infinihand' or 'mediapipe').
        weights: part ('full', 'geometry', 'crop_encoder') -> {name, sha256} of each configured
            checkpoint; {'seeded': {'seed': N}} for untrained seeded weights.
        engine_config_sha256: SHA-256 of the resolved engine settings (sorted JSON).
        engine_settings: the resolved engine settings themselves (``engine/settings.py``).
        package_version: the installed infinihand_ros version.

    """

    hand_source: str
    weights: dict[str, dict[str, Any]]
    engine_config_sha256: str
    engine_settings: dict[str, Any]
    package_version: str

    def to_dict(self) -> dict[str, Any]:
        """Return JSON-ready data."""
        return asdict(self)


def hand_source_of(config: EngineConfig) -> str:
    """Return the hand source the engine of ``config`` runs (``config.hands.source``)."""
    hands = getattr(config, 'hands', None)
    return str(getattr(hands, 'source', DEFAULT_HAND_SOURCE))


def files_sha256(path: Path) -> str:
    """Return the SHA-256 of a weight file, or of a directory's weight files in name order."""
    files = ([path] if path.is_file() else
             sorted(p for p in path.rglob('*') if p.is_file() and p.suffix in WEIGHT_SUFFIXES))
    digest = hashlib.sha256()
    for file in files:
        digest.update(file.relative_to(path).as_posix().encode() if file != path else b'')
        with file.open('rb') as handle:
            while chunk := handle.read(_CHUNK_BYTES):
                digest.update(chunk)
    return digest.hexdigest()


def _weights(config: EngineConfig) -> dict[str, dict[str, Any]]:
    selection = config.model
    parts = {'full': selection.checkpoint, 'geometry': selection.geometry_weights,
             'crop_encoder': selection.crop_encoder_weights}
    weights = {}
    for part, name in parts.items():
        if name is not None:
            path = resolve_checkpoint(name) if part == 'full' else Path(name).expanduser()
            weights[part] = {'name': name, 'sha256': files_sha256(Path(path))}
    return weights or {'seeded': {'seed': selection.seed}}


def provenance_of(config: EngineConfig) -> Provenance:
    """Return the provenance of episodes converted by an engine of ``config``.

    Raises:
        CheckpointError: when a configured checkpoint cannot be found.

    """
    resolved = config_to_dict(config)
    settings = json.dumps(resolved, sort_keys=True, default=str)
    return Provenance(hand_source=hand_source_of(config), weights=_weights(config),
                      engine_config_sha256=hashlib.sha256(settings.encode()).hexdigest(),
                      engine_settings=resolved,
                      package_version=importlib.metadata.version(PACKAGE))
