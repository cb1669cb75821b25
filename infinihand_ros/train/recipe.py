"""The recipe of a bundled model: its data, training stages, export and evaluations, in order.

A recipe file (section ``recipe``; ``models/tiny_synthetic/recipe.yaml``) holds
``training_sets`` (synthetic seeds), ``eval_sets``, ``settings`` (a training config,
``config/train_<name>.yaml`` or a path, plus dotted ``set`` values as ``train --set`` takes
them), ``stages`` in order (setting, steps, data sets, processes, ``init``: the earlier stage
whose final model it starts from, or null; optional ``set`` and ``init_input_size``),
``export`` and ``evaluations``. This module reads and checks it and builds each step's command;
``recipe_runner.py`` runs them. ``stage_config`` is the resolved config a stage trains with,
the one saved beside its checkpoints.
"""

from collections.abc import Iterator
from collections.abc import Mapping
import dataclasses
from dataclasses import dataclass
from dataclasses import field
from pathlib import Path
import sys
from typing import Any
from typing import Final

from infinihand_ros.core.config import config_from_dict
from infinihand_ros.core.config import read_yaml
from infinihand_ros.core.config import require_positive
from infinihand_ros.core.errors import ConfigError
from infinihand_ros.train.config_compose import apply_overrides
from infinihand_ros.train.train_config import load_train_config
from infinihand_ros.train.train_config import SECTION_CONFIGS
from infinihand_ros.train.train_config import TrainConfig
from infinihand_ros.train.train_state import CHECKPOINTS_DIR
from infinihand_ros.train.train_state import FINAL_NAME
from infinihand_ros.train.train_state import MODEL_DIR
import yaml

#: Top-level section of a recipe file.
RECIPE_SECTION: Final = 'recipe'
#: Frame rate of the training sets (Hz).
TRAIN_FPS: Final = 10


@dataclass(frozen=True)
class TrainingSet:
    """Synthetic training sequences ``runs/<name>/seed_<s>/samples``, one per seed."""

    name: str
    frames: int
    seeds: tuple[tuple[int, int], ...]
    size: tuple[int, int] = (224, 168)

    def __post_init__(self) -> None:
        """Refuse empty sequences and seed ranges that are empty or negative."""
        where = f'{RECIPE_SECTION}.training_sets[{self.name}]'
        require_positive(where, frames=self.frames)
        for first, last in self.seeds:
            if not 0 <= first <= last:
                raise ConfigError(f'{where}.seeds: [{first}, {last}] is no range of seeds')


@dataclass(frozen=True)
class EvalGroup:
    """Evaluation seeds (an inclusive range) at one frame rate (Hz)."""

    seeds: tuple[int, int]
    fps: int


@dataclass(frozen=True)
class EvalSet:
    """Evaluation sequences ``runs/<name>/seed_<s>_fps<f>`` (bag removed, samples kept)."""

    name: str
    groups: tuple[EvalGroup, ...]
    frames: int = 150
    size: tuple[int, int] = (320, 240)

    def sequences(self, runs: Path) -> Iterator[tuple[int, int, Path]]:
        """Yield (seed, fps, directory) of every sequence, in seed order."""
        for group in self.groups:
            for seed in range(group.seeds[0], group.seeds[1] + 1):
                yield seed, group.fps, runs / self.name / f'seed_{seed}_fps{group.fps}'


@dataclass(frozen=True)
class _SettingFields:
    name: str
    config: str


@dataclass(frozen=True)
class Setting(_SettingFields):
    """A training config (``config/train_<name>.yaml`` or a path) and its ``set`` values."""

    overrides: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class _StageFields:
    name: str
    setting: str
    steps: int
    processes: int
    init: str | None
    data: tuple[str, ...]
    init_input_size: tuple[int, int] | None = None

    def __post_init__(self) -> None:
        """Refuse a stage without processes or data, or a resized start without a start."""
        where = f'{RECIPE_SECTION}.stages[{self.name}]'
        require_positive(where, processes=self.processes)
        if not self.data:
            raise ConfigError(f'{where}.data: name at least one training set')
        if self.init_input_size is not None and self.init is None:
            raise ConfigError(f'{where}.init_input_size: needs an init stage')


@dataclass(frozen=True)
class Stage(_StageFields):
    """One training run ``runs/<name>`` from ``init``'s final model (None: seeded weights).

    ``init_input_size`` (width, height) starts from a copy of that model with its input size
    changed; ``overrides`` are set after the setting's.
    """

    overrides: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Export:
    """The bundled model: ``stage``'s final model in float16, written to ``runs/<out>``."""

    stage: str
    train_sets: tuple[str, ...]
    out: str


@dataclass(frozen=True)
class Evaluation:
    """``python -m infinihand_ros.eval`` on the export, its report in ``runs/<name>.md``."""

    name: str
    eval_set: str
    args: tuple[str, ...] = ()
    save_predictions: bool = False


@dataclass(frozen=True)
class _Plan:
    training_sets: tuple[TrainingSet, ...]
    eval_sets: tuple[EvalSet, ...]
    export: Export
    evaluations: tuple[Evaluation, ...] = ()


@dataclass(frozen=True)
class Recipe:
    """A whole recipe; every name it refers to is checked at construction."""

    training_sets: tuple[TrainingSet, ...]
    eval_sets: tuple[EvalSet, ...]
    settings: tuple[Setting, ...]
    stages: tuple[Stage, ...]
    export: Export
    evaluations: tuple[Evaluation, ...] = ()

    def __post_init__(self) -> None:
        """Refuse unknown or repeated names and a stage that starts from a later one."""
        for kind, items in (('training_sets', self.training_sets),
                            ('eval_sets', self.eval_sets), ('settings', self.settings)):
            names = [item.name for item in items]
            if len(set(names)) != len(names):
                raise ConfigError(f'{RECIPE_SECTION}.{kind}: names must differ, got {names}')
        sets = {item.name for item in self.training_sets}
        settings = {item.name for item in self.settings}
        earlier: set[str] = set()
        for stage in self.stages:
            where = f'{RECIPE_SECTION}.stages[{stage.name}]'
            _require_known(f'{where}.setting', [stage.setting], settings)
            _require_known(f'{where}.data', stage.data, sets)
            _require_known(f'{where}.init (an earlier stage)',
                           [stage.init] if stage.init else [], earlier)
            if stage.name in earlier:
                raise ConfigError(f'{where}: a second stage of that name')
            earlier.add(stage.name)
        export = self.export
        _require_known(f'{RECIPE_SECTION}.export.stage', [export.stage], earlier)
        _require_known(f'{RECIPE_SECTION}.export.train_sets', export.train_sets, sets)
        for evaluation in self.evaluations:
            _require_known(f'{RECIPE_SECTION}.evaluations[{evaluation.name}].eval_set',
                           [evaluation.eval_set], {item.name for item in self.eval_sets})

    def setting(self, name: str) -> Setting:
        """Return the setting called ``name``."""
        return next(item for item in self.settings if item.name == name)


def _require_known(where: str, names: Any, known: set[str]) -> None:
    """Raise ConfigError naming the first of ``names`` not in ``known``."""
    for name in names:
        if name not in known:
            raise ConfigError(f'{where}: unknown name {name!r}; known: {sorted(known)}')


def load_recipe(path: str | Path) -> Recipe:
    """Read a recipe file (section ``recipe``).

    Raises:
        ConfigError: for an unreadable file, a missing section, an unknown key, a wrong type, a
            bad ``set`` key or an unknown name, naming the key.

    """
    document = read_yaml(path)
    if not isinstance(document, dict) or not isinstance(document.get(RECIPE_SECTION), dict):
        raise ConfigError(f'{path}: no top-level section {RECIPE_SECTION!r}')
    section = dict(document[RECIPE_SECTION])
    where = f'{path}:{RECIPE_SECTION}'
    settings = tuple(_with_set(_SettingFields, Setting, item, f'{where}.settings[{index}]')
                     for index, item in enumerate(_items(section, 'settings', where)))
    stages = tuple(_with_set(_StageFields, Stage, item, f'{where}.stages[{index}]')
                   for index, item in enumerate(_items(section, 'stages', where)))
    plan = config_from_dict(_Plan, section, where)
    try:
        return Recipe(plan.training_sets, plan.eval_sets, settings, stages, plan.export,
                      plan.evaluations)
    except ConfigError as exc:
        raise ConfigError(f'{path}:{exc}') from exc


def _items(section: dict[str, Any], key: str, where: str) -> list[Any]:
    """Pop ``section[key]``, which must be a non-empty list."""
    items = section.pop(key, None)
    if not isinstance(items, list) or not items:
        raise ConfigError(f'{where}.{key}: expected a non-empty list, got {items!r}')
    return items


def _with_set(fields_cls: type, cls: type, item: Any, where: str) -> Any:
    """Build ``cls`` from a mapping: its ``set`` (dotted keys, checked) and the typed rest."""
    if not isinstance(item, dict):
        raise ConfigError(f'{where}: expected a mapping, got {item!r}')
    item = dict(item)
    overrides = item.pop('set', None) or {}
    if not isinstance(overrides, dict):
        raise ConfigError(f'{where}.set: expected a mapping of dotted keys, got {overrides!r}')
    try:
        apply_overrides({}, overrides, SECTION_CONFIGS)
    except ConfigError as exc:
        raise ConfigError(f'{where}.set: {exc}') from exc
    typed = config_from_dict(fields_cls, item, where)
    values = {name.name: getattr(typed, name.name) for name in dataclasses.fields(typed)}
    return cls(**values, overrides=dict(overrides))


def final_model(runs: Path, stage: str) -> Path:
    """Return the final model directory of the stage called ``stage``."""
    return runs / stage / CHECKPOINTS_DIR / FINAL_NAME / MODEL_DIR


def stage_init(stage: Stage, runs: Path) -> str | None:
    """Return the checkpoint ``stage`` starts from (None: seeded weights)."""
    if stage.init is None:
        return None
    if stage.init_input_size is not None:
        return str(runs / f'{stage.name}_init')
    return str(final_model(runs, stage.init))


def stage_overrides(recipe: Recipe, stage: Stage, runs: Path) -> dict[str, Any]:
    """Return the dotted values ``stage`` sets on its setting's config (``train --set``)."""
    return {**recipe.setting(stage.setting).overrides, **stage.overrides,
            'train.steps': stage.steps,
            'train.data.sequences': [str(runs / name) for name in stage.data],
            'train.model.init_checkpoint': stage_init(stage, runs)}


def stage_config(recipe: Recipe, stage: Stage, runs: Path) -> TrainConfig:
    """Return the resolved config ``stage`` trains with (saved beside its checkpoints)."""
    return load_train_config(recipe.setting(stage.setting).config,
                             stage_overrides(recipe, stage, runs))


def train_command(recipe: Recipe, stage: Stage, runs: Path) -> list[str]:
    """Return the command that trains ``stage``, or continues it if it has checkpoints."""
    launch = [sys.executable, '-m', 'infinihand_ros.train']
    if stage.processes > 1:
        launch[2:2] = ['torch.distributed.run', '--standalone', '--nproc-per-node',
                       str(stage.processes), '-m']
    output = runs / stage.name
    if (output / CHECKPOINTS_DIR).is_dir():
        return [*launch, '--resume', str(output), '--no-progress']
    values = [f'{key}={_yaml_value(value)}'
              for key, value in stage_overrides(recipe, stage, runs).items()]
    return [*launch, '--config', recipe.setting(stage.setting).config, '--output', str(output),
            '--set', *values, '--no-progress']


def _yaml_value(value: Any) -> str:
    """Return ``value`` as one line of YAML flow text."""
    return yaml.safe_dump([value], default_flow_style=True, width=2 ** 20).strip()[1:-1]


def training_set_commands(item: TrainingSet, runs: Path) -> list[list[str]]:
    """Return one ``synth.batch`` command per seed range (seeds already written are skipped)."""
    width, height = item.size
    return [[sys.executable, '-m', 'infinihand_ros.synth.batch', '--out', str(runs / item.name),
             '--seeds', str(first), str(last), '--frames', str(item.frames),
             '--fps', str(TRAIN_FPS), '--width', str(width), '--height', str(height)]
            for first, last in item.seeds]


def eval_sequence_command(item: EvalSet, seed: int, fps: int, directory: Path) -> list[str]:
    """Return the ``synth`` command that writes one evaluation sequence."""
    width, height = item.size
    return [sys.executable, '-m', 'infinihand_ros.synth', '--out', str(directory),
            '--seed', str(seed), '--frames', str(item.frames), '--fps', str(fps),
            '--width', str(width), '--height', str(height), '--image-codec', 'jpeg']


def export_command(recipe: Recipe, runs: Path) -> list[str]:
    """Return the command that exports the bundled model to ``runs/<export.out>``."""
    export = recipe.export
    return [sys.executable, '-m', 'infinihand_ros.eval.model_export',
            '--checkpoint', str(final_model(runs, export.stage)),
            '--out', str(runs / export.out),
            '--train-sequences', *(str(runs / name) for name in export.train_sets),
            '--overwrite']


def evaluation_command(recipe: Recipe, evaluation: Evaluation, runs: Path) -> list[str]:
    """Return the evaluation command of ``evaluation`` on the export."""
    eval_set = next(item for item in recipe.eval_sets if item.name == evaluation.eval_set)
    sequences = [str(directory) for _, _, directory in eval_set.sequences(runs)]
    saved = ['--save-predictions', str(runs / evaluation.name)] if evaluation.save_predictions \
        else []
    return [sys.executable, '-m', 'infinihand_ros.eval',
            '--checkpoint', str(runs / recipe.export.out), '--sequences', *sequences,
            *evaluation.args, *saved]
