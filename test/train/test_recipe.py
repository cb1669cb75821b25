"""The bundled model's recipe: it parses, every stage resolves, and it runs (dry) in order."""

from pathlib import Path

from infinihand_ros.core.errors import ConfigError
from infinihand_ros.train.cli import build_parser
from infinihand_ros.train.config_compose import parse_override
from infinihand_ros.train.recipe import load_recipe
from infinihand_ros.train.recipe import Recipe
from infinihand_ros.train.recipe import stage_config
from infinihand_ros.train.recipe import train_command
from infinihand_ros.train.recipe_runner import main
from infinihand_ros.train.recipe_runner import write_resized_init
from infinihand_ros.train.train_config import load_train_config
from infinihand_ros.train.train_config import STAGE_2
from infinihand_ros.train.train_state import CHECKPOINTS_DIR
import pytest
import yaml

MODEL_DIR = Path(__file__).parents[2] / 'models' / 'tiny_synthetic'
RECIPE = MODEL_DIR / 'recipe.yaml'
RUNS = Path('runs')


@pytest.fixture(scope='module')
def recipe() -> Recipe:
    return load_recipe(RECIPE)


def test_every_stage_resolves_through_the_loader(recipe: Recipe) -> None:
    """Each stage: its setting's config, set values, steps, data and start, all accepted."""
    for previous, stage in zip((None, *recipe.stages), recipe.stages):
        config = stage_config(recipe, stage, RUNS)
        assert config.steps == stage.steps
        assert config.data.sequences == tuple(str(RUNS / name) for name in stage.data)
        assert stage.init == (previous.name if previous else None)  # one line of descent
    assert recipe.export.stage == recipe.stages[-1].name


@pytest.mark.parametrize('name', ['23_heads', '22_heads', '15_joint'])
def test_the_saved_configs_of_the_last_stages_are_what_the_recipe_resolves(
        recipe: Recipe, name: str) -> None:
    """The resolved configs beside the model (from the full files they trained with) match."""
    stage = next(stage for stage in recipe.stages if stage.name == name)
    saved = load_train_config(MODEL_DIR / f'train_config_{name}.yaml')
    assert stage_config(recipe, stage, RUNS) == saved
    assert (saved.stage == STAGE_2) == (name == '15_joint')


def test_the_train_command_sets_exactly_the_stage_config(recipe: Recipe, tmp_path: Path) -> None:
    """The --set values a stage passes read back (YAML) to the same resolved config."""
    runs = tmp_path / 'runs'  # no checkpoints: every stage starts (none resumes)
    for stage in recipe.stages:
        command = train_command(recipe, stage, runs)
        args = build_parser().parse_args(command[command.index('--config'):])
        overrides = dict(parse_override(text) for text in args.overrides)
        assert load_train_config(args.config, overrides) == stage_config(recipe, stage, runs)
        assert ('torch.distributed.run' in command) == (stage.processes > 1)


def test_the_seeds_of_the_data_sets_do_not_overlap(recipe: Recipe) -> None:
    ranges = [pair for item in recipe.training_sets for pair in item.seeds]
    ranges += [group.seeds for item in recipe.eval_sets for group in item.groups]
    ranges.sort()
    assert all(first <= last for first, last in ranges)
    assert all(earlier[1] < later[0] for earlier, later in zip(ranges, ranges[1:]))


def _write_recipe(tmp_path: Path, edit) -> Path:
    document = yaml.safe_load(RECIPE.read_text(encoding='utf-8'))
    edit(document['recipe'])
    path = tmp_path / 'recipe.yaml'
    path.write_text(yaml.safe_dump(document), encoding='utf-8')
    return path


@pytest.mark.parametrize('edit, message', [
    (lambda r: r['stages'][0].update(setting='stage3'), r'stages\[01_stage1\]\.setting'),
    (lambda r: r['stages'][1].update(init='19_heads'), r'init \(an earlier stage\)'),
    (lambda r: r['stages'][0].update(data=['synth_none']), r'unknown name \'synth_none\''),
    (lambda r: r['stages'][0].update(steps='many'), r'stages\[0\]\.steps: expected int'),
    (lambda r: r['settings'][2]['set'].update({'train.clip.stride': 2}),
     r"settings\[2\]\.set: --set train\.clip\.stride: train\.clip has no key 'stride'"),
    (lambda r: r['export'].update(stage='24_heads'), r'export\.stage'),
    (lambda r: r['training_sets'][1].update(name='synth_train'), r'names must differ'),
    (lambda r: r['training_sets'][0].update(seeds=[[5, 4]]), r'\[5, 4\] is no range'),
])
def test_recipe_errors_name_the_key(tmp_path: Path, edit, message: str) -> None:
    with pytest.raises(ConfigError, match=message):
        load_recipe(_write_recipe(tmp_path, edit))


def test_a_dry_run_skips_finished_stages_and_resumes_started_ones(
        recipe: Recipe, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """Stage 1 finished, stage 2 started: 1 resumed, the rest new, then export and eval."""
    final = tmp_path / '01_stage1' / CHECKPOINTS_DIR / 'final' / 'model'
    final.mkdir(parents=True)
    (final / 'model.safetensors').write_bytes(b'')
    (tmp_path / '02_stage2' / CHECKPOINTS_DIR).mkdir(parents=True)
    assert main([str(RECIPE), '--runs', str(tmp_path), '--dry-run']) == 0
    lines = capsys.readouterr().out.splitlines()
    trains = [line for line in lines if '-m infinihand_ros.train ' in line]
    assert len(trains) == len(recipe.stages) - 1
    assert f'--resume {tmp_path / "02_stage2"}' in trains[0]
    assert all('--config' in line for line in trains[1:])
    seeds = sum(last - first + 1 for item in recipe.eval_sets for group in item.groups
                for first, last in [group.seeds])
    assert sum('-m infinihand_ros.synth --out' in line for line in lines) == seeds
    assert sum('-m infinihand_ros.eval ' in line for line in lines) == len(recipe.evaluations)
    assert not any(tmp_path.glob('synth_*'))  # a dry run writes nothing


def test_a_resized_start_is_the_init_model_with_the_new_input_size(recipe: Recipe,
                                                                   tmp_path: Path) -> None:
    stage = next(stage for stage in recipe.stages if stage.init_input_size is not None)
    source = tmp_path / stage.init / CHECKPOINTS_DIR / 'final' / 'model'
    source.mkdir(parents=True)
    (source / 'model.safetensors').write_bytes(b'weights')
    geometry = {'geometry': {'aggregator': {'image_height': 168, 'image_width': 224,
                                            'patch_size': 14}}}
    (source / 'geometry.yaml').write_text(yaml.safe_dump(geometry), encoding='utf-8')
    write_resized_init(stage, tmp_path)
    target = tmp_path / f'{stage.name}_init'
    assert (target / 'model.safetensors').read_bytes() == b'weights'
    written = yaml.safe_load((target / 'geometry.yaml').read_text())['geometry']['aggregator']
    assert (written['image_width'], written['image_height']) == stage.init_input_size
    assert written['patch_size'] == 14
