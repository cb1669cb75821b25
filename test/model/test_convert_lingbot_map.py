"""Tests of model/io/convert_lingbot_map.py on small checkpoints in the upstream key layout."""

import json
from pathlib import Path

from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.model.config import load_geometry_config
from infinihand_ros.model.config import named_config_path
from infinihand_ros.model.geometry_model import GeometryModel
from infinihand_ros.model.hand.config import HandBranchConfig
from infinihand_ros.model.io.checkpoint import config_to_yaml
from infinihand_ros.model.io.checkpoint import read_checkpoint
from infinihand_ros.model.io.compose import load_composed_model
from infinihand_ros.model.io.convert_lingbot_map import check_geometry_tensors
from infinihand_ros.model.io.convert_lingbot_map import convert_checkpoint
from infinihand_ros.model.io.convert_lingbot_map import convert_lingbot_map
from infinihand_ros.model.io.convert_lingbot_map import convert_vggt
from infinihand_ros.model.io.convert_lingbot_map import main
from infinihand_ros.model.io.torch_checkpoint import read_torch_checkpoint
from infinihand_ros.model.pose_encoding import encoding_to_cam_to_world
import numpy as np
import pytest
import torch

UPSTREAM = ('aggregator.', 'camera_head.', 'depth_head.')
LINGBOT_MAP_KEYS = Path('/work/shared/design/keys/lingbot_map_gctstream.json')
#: A camera at (1, 2, 3) in the raw encoding, turned a quarter about z.
ENCODING = torch.tensor([[1.0, 2.0, 3.0, 0.0, 0.0, 0.5 ** 0.5, 0.5 ** 0.5, 0.9, 1.1]],
                        dtype=torch.float64)


def _upstream_state(model: GeometryModel) -> dict[str, torch.Tensor]:
    """Return the model's upstream-named tensors, randomised so that a copy is detectable."""
    generator = torch.Generator().manual_seed(3)
    return {key: torch.randn(value.shape, generator=generator)
            for key, value in model.state_dict().items() if key.startswith(UPSTREAM)}


def _write_config(tmp_path, model: GeometryModel):
    """Write the model's configuration as a YAML file and return its path."""
    path = tmp_path / 'model.yaml'
    path.write_text(config_to_yaml(model.config))
    return path


def test_lingbot_map_wrapped_and_prefixed_loads_by_identity(
        micro_model, hand_config: HandBranchConfig, tmp_path) -> None:
    """A {"model": {"module." + key}} checkpoint with a point head converts key for key."""
    state = _upstream_state(micro_model)
    wrapped = {'module.' + key: value for key, value in state.items()}
    wrapped['module.point_head.norm.weight'] = torch.ones(3)
    torch.save({'model': wrapped, 'epoch': 3}, tmp_path / 'lingbot.pt')
    conversion, report = convert_checkpoint('lingbot-map', tmp_path / 'lingbot.pt',
                                            _write_config(tmp_path, micro_model),
                                            tmp_path / 'out')
    assert conversion.dropped == ('point_head.norm.weight',)
    assert report.matched == len(state) and report.missing == ()
    assert report.allowed_missing and all(key.startswith('mask_head.')
                                          for key in report.allowed_missing)
    written = read_checkpoint(tmp_path / 'out')
    assert written.tensors.keys() == {f'geometry.{key}' for key in state}
    assert written.metadata['source'] == 'lingbot-map: lingbot.pt'
    loaded, _ = load_composed_model(geometry=tmp_path / 'out', hand_config=hand_config)
    for key, value in state.items():
        assert torch.equal(loaded.geometry.state_dict()[key], value), key
    mask = loaded.geometry.mask_head.state_dict()
    assert torch.equal(mask['scratch.layer1_rn.weight'],
                       state['depth_head.scratch.layer1_rn.weight'])


@pytest.mark.parametrize('source, direction, inverted', [
    ('lingbot-map', 'cam_to_world', False), ('vggt', 'world_to_cam', True)])
def test_converted_checkpoint_records_the_upstream_conventions(
        micro_model, tmp_path, source: str, direction: str, inverted: bool) -> None:
    """The converter records the weights' pose direction and preprocessing; decoding follows."""
    state = _upstream_state(micro_model)
    if source == 'vggt':
        del state['aggregator.scale_token']
    torch.save(state, tmp_path / 'upstream.pt')
    convert_checkpoint(source, tmp_path / 'upstream.pt', _write_config(tmp_path, micro_model),
                       tmp_path / 'out')
    config = read_checkpoint(tmp_path / 'out').geometry_config
    assert (config.pose_direction, config.preprocessing) == (direction, 'resize_crop')
    assert config.aggregator.global_rope == ('spatial2d' if source == 'vggt' else 'video3d')
    T_world_cam, _ = encoding_to_cam_to_world(ENCODING, 56, 70, config.pose_direction)
    centre = [-2.0, 1.0, -3.0] if inverted else [1.0, 2.0, 3.0]
    np.testing.assert_allclose(T_world_cam[0, :3, 3].numpy(), centre, atol=1e-12)


def test_cli_pose_direction_overrides_the_upstream_one(micro_model, tmp_path, capsys) -> None:
    torch.save(_upstream_state(micro_model), tmp_path / 'lingbot.pt')
    args = ['--source', 'lingbot-map', '--input', str(tmp_path / 'lingbot.pt'), '--config',
            str(_write_config(tmp_path, micro_model)), '--output', str(tmp_path / 'out')]
    assert main([*args, '--pose-direction', 'world_to_cam']) == 0
    assert 'pose_direction world_to_cam, preprocessing resize_crop' in capsys.readouterr().out
    assert read_checkpoint(tmp_path / 'out').geometry_config.pose_direction == 'world_to_cam'
    with pytest.raises(SystemExit) as info:
        main(args)  # --output exists now
    assert info.value.code == 2 and 'already exists' in capsys.readouterr().err


def test_vggt_gets_a_scale_token_and_loses_extra_heads(micro_model, tmp_path) -> None:
    """VGGT keys convert with a zero scale token; point/track heads are dropped."""
    state = _upstream_state(micro_model)
    del state['aggregator.scale_token']
    state['track_head.tracker.fc.weight'] = torch.ones(2, 2)
    torch.save(state, tmp_path / 'vggt.pt')
    conversion = convert_vggt(read_torch_checkpoint(tmp_path / 'vggt.pt'))
    assert conversion.added == ('aggregator.scale_token',)
    assert conversion.dropped == ('track_head.tracker.fc.weight',)
    assert conversion.state_dict['aggregator.scale_token'].abs().sum() == 0
    with pytest.raises(CheckpointError, match='use --source lingbot-map'):
        convert_vggt(_upstream_state(micro_model))


def test_unknown_keys_and_shape_mismatches_are_errors(
        micro_model, make_micro_config, tmp_path) -> None:
    """An unexpected key or a wrong shape stops the conversion with CheckpointError."""
    state = _upstream_state(micro_model)
    torch.save({**state, 'decoder.weight': torch.ones(1)}, tmp_path / 'odd.pt')
    config = _write_config(tmp_path, micro_model)
    with pytest.raises(CheckpointError, match='decoder.weight'):
        convert_checkpoint('lingbot-map', tmp_path / 'odd.pt', config, tmp_path / 'a')
    bigger = GeometryModel(make_micro_config(embed_dim=96))
    torch.save(_upstream_state(bigger), tmp_path / 'big.pt')
    with pytest.raises(CheckpointError, match='shape') as info:
        convert_checkpoint('lingbot-map', tmp_path / 'big.pt', config, tmp_path / 'b')
    assert 'mask_head' not in str(info.value)  # allowed to be missing: not listed
    del state['depth_head.norm.weight']
    torch.save(state, tmp_path / 'cut.pt')
    with pytest.raises(CheckpointError, match='missing: depth_head.norm.weight'):
        convert_checkpoint('lingbot-map', tmp_path / 'cut.pt', config, tmp_path / 'c')
    assert not any((tmp_path / name).exists() for name in 'abc')


def test_pickled_objects_are_refused(tmp_path) -> None:
    """weights_only loading rejects arbitrary pickled objects."""
    torch.save({'model': {'x': object()}}, tmp_path / 'evil.pt')
    with pytest.raises(CheckpointError, match='weights-only'):
        read_torch_checkpoint(tmp_path / 'evil.pt')


def test_cli_reports_errors_in_one_line(tmp_path, capsys) -> None:
    """A bad checkpoint makes the CLI exit 1 with an error line."""
    (tmp_path / 'empty.pt').write_bytes(b'not a checkpoint')
    status = main(['--source', 'lingbot-map', '--input', str(tmp_path / 'empty.pt'),
                   '--output', str(tmp_path / 'out')])
    assert status == 1
    assert capsys.readouterr().err.startswith('error: ')


@pytest.mark.skipif(not LINGBOT_MAP_KEYS.is_file(), reason='LingBot-Map key reference absent')
def test_real_lingbot_map_keys_fit_the_paper_config() -> None:
    """The reference's 1,342 keys fit the paper config; only the mask head is left to loading."""
    reference = json.loads(LINGBOT_MAP_KEYS.read_text())['keys']
    state = {key: torch.empty(shape, device='meta') for key, shape in reference.items()}
    config = load_geometry_config(named_config_path('paper'))
    report = check_geometry_tensors(config, convert_lingbot_map(state).state_dict, 'reference')
    assert report.matched == 1342 and report.ok
    assert {key.split('.')[0] for key in report.allowed_missing} == {'mask_head'}
