"""Loading one model from checkpoint parts, with a loading report by branch.

The parts: a whole-model checkpoint, a geometry checkpoint (e.g. converted LingBot-Map weights)
and a crop-encoder checkpoint (e.g. converted WiLoR weights).

``load_composed_model`` builds the model seeded (``build_infinihand_model``), then loads each
part given, in the order full -> geometry -> crop encoder (later parts replace earlier ones):

- ``full``: every tensor of the model except the hand models'; its two configs.
- ``geometry``: ``geometry.*`` only, and its ``geometry.yaml``. It may leave out the whole
  ``geometry.mask_head`` (upstream weights have none): the mask head is then seeded from the
  loaded depth head with a fresh final layer (paper Sec. 3.2).
- ``crop_encoder``: ``hand_branch.backbone.*`` only, and its ``hand_branch.yaml``.

Each part must hold all the keys of its role, and nothing else, with the model's shapes.
Everything no part provides keeps its seeded weights. The configs come from the parts (the
geometry part's, else the full checkpoint's; the full checkpoint's hand-branch config, else the
crop encoder's, whose appearance ViT must then match), else from the caller. The hand models'
tensors are never in a checkpoint and never reported (they come from the hand models passed).
Every difference is checked before anything is loaded; the report groups them by branch.
"""

from dataclasses import dataclass
from dataclasses import field
from pathlib import Path
from typing import Final

from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.mano.base import HandModel
from infinihand_ros.model.config import GeometryConfig
from infinihand_ros.model.geometry_model import GeometryModel
from infinihand_ros.model.hand.config import HandBranchConfig
from infinihand_ros.model.heads.mask_head import init_mask_head_from_depth
from infinihand_ros.model.infinihand_model import build_infinihand_model
from infinihand_ros.model.infinihand_model import GEOMETRY_PREFIX
from infinihand_ros.model.infinihand_model import HAND_BRANCH_PREFIX
from infinihand_ros.model.infinihand_model import HAND_MODELS_PREFIX
from infinihand_ros.model.infinihand_model import InfiniHandModel
from infinihand_ros.model.io.checkpoint import CheckpointContents
from infinihand_ros.model.io.checkpoint import describe_keys
from infinihand_ros.model.io.checkpoint import read_checkpoint
import torch

FULL: Final = 'full'
GEOMETRY: Final = 'geometry'
CROP_ENCODER: Final = 'crop_encoder'
#: Keys each role must provide (and may only provide).
ROLE_PREFIXES: Final = {FULL: (GEOMETRY_PREFIX, HAND_BRANCH_PREFIX), GEOMETRY: (GEOMETRY_PREFIX,),
                        CROP_ENCODER: (f'{HAND_BRANCH_PREFIX}backbone.',)}
MASK_HEAD_PREFIX: Final = f'{GEOMETRY_PREFIX}mask_head.'
DEPTH_HEAD: Final = f'{GEOMETRY_PREFIX}depth_head'
#: The branches of the report, by key prefix.
BRANCHES: Final = (('geometry', GEOMETRY_PREFIX), ('hand_branch', HAND_BRANCH_PREFIX))


@dataclass(frozen=True)
class BranchReport:
    """How one branch's weights were filled.

    Attributes:
        branch: ``geometry`` or ``hand_branch``.
        loaded: number of tensors loaded, by checkpoint (later parts counted where they won).
        seeded: modules (e.g. ``hand_branch.adapter``) that keep their seeded initialisation.
        derived: modules initialised from another, with how (e.g. the mask head).
        missing: keys a part had to provide and lacks (errors).
        unexpected: keys a part has that the model or its role has not (errors).
        mismatched: (key, model shape, checkpoint shape) (errors).

    """

    branch: str
    loaded: dict[str, int] = field(default_factory=dict)
    seeded: tuple[str, ...] = ()
    derived: dict[str, str] = field(default_factory=dict)
    missing: tuple[str, ...] = ()
    unexpected: tuple[str, ...] = ()
    mismatched: tuple[tuple[str, tuple[int, ...], tuple[int, ...]], ...] = ()

    @property
    def ok(self) -> bool:
        """Return True when the branch has no missing, unexpected or mismatched keys."""
        return not (self.missing or self.unexpected or self.mismatched)

    def describe(self) -> list[str]:
        """Return readable lines for this branch."""
        lines = [f'{self.branch}:']
        lines += [f'  loaded {count} tensors from {source}' for source, count in
                  self.loaded.items()]
        lines += [f'  {module}: {how}' for module, how in self.derived.items()]
        if self.seeded:
            lines.append(f'  seeded (untrained): {", ".join(self.seeded)}')
        lines += describe_keys('missing', self.missing)
        lines += describe_keys('unexpected', self.unexpected)
        lines += [f'  shape of {key}: model {list(ours)}, checkpoint {list(theirs)}'
                  for key, ours, theirs in self.mismatched[:10]]
        return lines


@dataclass(frozen=True)
class ComposedLoadReport:
    """The loading report of ``load_composed_model``, grouped by branch.

    Attributes:
        branches: one report per branch (geometry, hand_branch).
        config_sources: where each branch's config came from (a file or ``caller``).

    """

    branches: tuple[BranchReport, ...]
    config_sources: dict[str, str]

    @property
    def ok(self) -> bool:
        """Return True when every branch loaded cleanly."""
        return all(branch.ok for branch in self.branches)

    def branch(self, name: str) -> BranchReport:
        """Return the report of branch ``name`` (``geometry`` or ``hand_branch``)."""
        return next(report for report in self.branches if report.branch == name)

    def describe(self) -> str:
        """Return a readable multi-line summary."""
        lines = [f'config of {name}: {source}' for name, source in self.config_sources.items()]
        for report in self.branches:
            lines += report.describe()
        return '\n'.join(lines)


def _resolve_configs(parts: dict[str, CheckpointContents],
                     geometry_config: GeometryConfig | None,
                     hand_config: HandBranchConfig | None
                     ) -> tuple[GeometryConfig, HandBranchConfig, dict[str, str]]:
    """Return the configs to build (parts first, then the caller's) and their sources."""
    sources = {}
    geometry_sources = [(role, parts[role]) for role in (GEOMETRY, FULL) if role in parts]
    if geometry_sources:
        role, part = geometry_sources[0]
        geometry_config, sources['geometry'] = part.geometry_config, f'{part.path} ({role})'
    elif geometry_config is not None:
        sources['geometry'] = 'caller'
    hand_sources = [(role, parts[role]) for role in (FULL, CROP_ENCODER) if role in parts]
    if hand_sources:
        role, part = hand_sources[0]
        hand_config, sources['hand_branch'] = part.hand_config, f'{part.path} ({role})'
    elif hand_config is not None:
        sources['hand_branch'] = 'caller'
    if geometry_config is None or hand_config is None:
        missing, argument = (('geometry', 'geometry_config') if geometry_config is None
                             else ('hand-branch', 'hand_config'))
        raise CheckpointError(f'no {missing} config: no checkpoint given has one; pass '
                              f'{argument}, e.g. the config the engine names')
    encoder = parts.get(CROP_ENCODER)
    if encoder is not None and encoder.hand_config.appearance != hand_config.appearance:
        raise CheckpointError(f'{encoder.path}: its appearance ViT config differs from the hand '
                              f'branch of {sources["hand_branch"]}; convert it with that '
                              'hand-branch config')
    return geometry_config, hand_config, sources


def _role_errors(role: str, part: CheckpointContents, expected: dict[str, tuple[int, ...]]
                 ) -> tuple[list[str], list[str], list[tuple[str, tuple, tuple]]]:
    """Return (missing, unexpected, mismatched) of one part against its role's keys."""
    prefixes = ROLE_PREFIXES[role]
    scope = {key: shape for key, shape in expected.items() if key.startswith(prefixes)}
    missing = [key for key in scope if key not in part.tensors]
    if role == GEOMETRY and all(key.startswith(MASK_HEAD_PREFIX) for key in missing):
        missing = []  # no mask head at all: it is derived from the depth head
    unexpected = [key for key in part.tensors if key not in scope]
    mismatched = [(key, scope[key], tuple(tensor.shape)) for key, tensor in part.tensors.items()
                  if key in scope and scope[key] != tuple(tensor.shape)]
    return missing, unexpected, mismatched


def _module(key: str) -> str:
    """Return the top-level module of a whole-model key, e.g. ``geometry.depth_head``."""
    return '.'.join(key.split('.')[:2])


def _branch_reports(parts: dict[str, CheckpointContents], expected: dict[str, tuple[int, ...]],
                    derived: dict[str, str]) -> tuple[BranchReport, ...]:
    """Return the per-branch reports: what each part fills, what stays seeded, the errors."""
    winner: dict[str, str] = {}
    missing, unexpected, mismatched = [], [], []
    for role, part in parts.items():
        role_missing, role_unexpected, role_mismatched = _role_errors(role, part, expected)
        missing += role_missing
        unexpected += role_unexpected
        mismatched += role_mismatched
        winner.update({key: part.source for key in part.tensors if key in expected})
    reports = []
    for name, prefix in BRANCHES:
        loaded: dict[str, int] = {}
        for key in expected:
            if key.startswith(prefix) and key in winner:
                loaded[winner[key]] = loaded.get(winner[key], 0) + 1
        seeded = sorted({_module(key) for key in expected
                         if key.startswith(prefix) and key not in winner} - set(derived))
        reports.append(BranchReport(
            name, loaded, tuple(seeded),
            {module: how for module, how in derived.items() if module.startswith(prefix)},
            tuple(key for key in missing if key.startswith(prefix)),
            tuple(key for key in unexpected if key.startswith(prefix)),
            tuple(item for item in mismatched if item[0].startswith(prefix))))
    return tuple(reports)


def _check_roles(parts: dict[str, CheckpointContents]) -> None:
    """Raise CheckpointError for a part that lacks the configs of its role."""
    needs = {FULL: (True, True), GEOMETRY: (True, False), CROP_ENCODER: (False, True)}
    for role, part in parts.items():
        has = (part.geometry_config is not None, part.hand_config is not None)
        if any(need and not present for need, present in zip(needs[role], has)):
            fits = [other for other, need in needs.items() if need == has]
            hint = f'pass it as {fits[0]}=' if fits else 'it holds no weights of either branch'
            raise CheckpointError(f'{part.path}: not a {role} checkpoint (geometry: {has[0]}, '
                                  f'hand branch: {has[1]}); {hint}')


def load_composed_model(*, full: str | Path | None = None, geometry: str | Path | None = None,
                        crop_encoder: str | Path | None = None,
                        geometry_config: GeometryConfig | None = None,
                        hand_config: HandBranchConfig | None = None, seed: int = 0,
                        hand_models: tuple[HandModel, HandModel] | None = None,
                        device: str | torch.device = 'cpu'
                        ) -> tuple[InfiniHandModel, ComposedLoadReport]:
    """Build one model from checkpoint parts; what no part provides is seeded.

    Args:
        full: a whole-model checkpoint directory (``save_infinihand_checkpoint``), or None.
        geometry: a geometry checkpoint directory (``convert_lingbot_map``), or None.
        crop_encoder: a crop-encoder checkpoint directory (``convert_wilor``), or None.
        geometry_config: the geometry config when no part has one (e.g. the engine's).
        hand_config: the hand-branch config when no part has one.
        seed: seed of every weight no part provides (the caller's random state is kept).
        hand_models: (left, right) hand models, e.g. real MANO; the built-in skeletons if None.
        device: device of the returned model.

    Returns:
        The model in eval mode on ``device`` and the report by branch.

    Raises:
        CheckpointError: for an unreadable or mis-laid part, a missing config, or any missing,
            unexpected or shape-mismatched key (all listed by branch; nothing is loaded).
        ConfigError: for a bad or incomplete config file in a part.

    """
    paths = {FULL: full, GEOMETRY: geometry, CROP_ENCODER: crop_encoder}
    parts = {role: read_checkpoint(path) for role, path in paths.items() if path is not None}
    _check_roles(parts)
    geometry_config, hand_config, sources = _resolve_configs(parts, geometry_config, hand_config)
    model = build_infinihand_model(geometry_config, hand_config, seed=seed,
                                   hand_models=hand_models)
    expected = {key: tuple(value.shape) for key, value in model.state_dict().items()
                if not key.startswith(HAND_MODELS_PREFIX)}
    merged = {key: tensor for part in parts.values() for key, tensor in part.tensors.items()}
    derived = {}
    if any(key.startswith(GEOMETRY_PREFIX) for key in merged) and not any(
            key.startswith(MASK_HEAD_PREFIX) for key in merged):
        derived[MASK_HEAD_PREFIX.rstrip('.')] = (f'seeded from the loaded {DEPTH_HEAD}, fresh '
                                                 'final layer (paper Sec. 3.2)')
    report = ComposedLoadReport(_branch_reports(parts, expected, derived), sources)
    if not report.ok:
        raise CheckpointError(f'{report.describe()}\nThe checkpoints do not fit the model; '
                              'convert them with the configs they were trained with.')
    model.load_state_dict(merged, strict=False)  # every key was checked above
    if derived:
        _seed_mask_head(model.geometry, seed)
    return model.to(device).eval(), report


def _seed_mask_head(geometry: GeometryModel, seed: int) -> None:
    """Initialise the mask head from the loaded depth head; the caller's random state is kept."""
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        init_mask_head_from_depth(geometry.mask_head, geometry.depth_head)


def load_infinihand_checkpoint(directory: str | Path,
                               hand_models: tuple[HandModel, HandModel] | None = None,
                               device: str | torch.device = 'cpu'
                               ) -> tuple[InfiniHandModel, ComposedLoadReport]:
    """Load a whole-model checkpoint strictly (``load_composed_model(full=directory)``).

    Raises:
        CheckpointError: for a missing or partial checkpoint or any key or shape difference.
        ConfigError: for a bad or incomplete config file.

    """
    return load_composed_model(full=directory, hand_models=hand_models, device=device)
