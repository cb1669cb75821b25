"""Tests of model/convert.py on small checkpoints written with upstream names and layouts."""

from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.model.checkpoint import config_to_yaml
from infinihand_ros.model.checkpoint import load_checkpoint
from infinihand_ros.model.convert import convert_checkpoint
from infinihand_ros.model.convert import convert_vggt
from infinihand_ros.model.convert import main
from infinihand_ros.model.convert import read_torch_checkpoint
from infinihand_ros.model.geometry_model import GeometryModel
import pytest
import torch

UPSTREAM = ('aggregator.', 'camera_head.', 'depth_head.')


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


def test_lingbot_map_wrapped_and_prefixed_loads_by_identity(micro_model, tmp_path) -> None:
    """A {"model": {"module." + key}} checkpoint with a point head converts key for key."""
    state = _upstream_state(micro_model)
    wrapped = {'module.' + key: value for key, value in state.items()}
    wrapped['module.point_head.norm.weight'] = torch.ones(3)
    torch.save({'model': wrapped, 'epoch': 3}, tmp_path / 'lingbot.pt')
    conversion, report = convert_checkpoint('lingbot-map', tmp_path / 'lingbot.pt',
                                            _write_config(tmp_path, micro_model),
                                            tmp_path / 'out')
    assert conversion.dropped == ('point_head.norm.weight',)
    assert report.matched == len(state)
    assert all(key.startswith('mask_head.') for key in report.missing)
    loaded = load_checkpoint(tmp_path / 'out')
    for key, value in state.items():
        assert torch.equal(loaded.state_dict()[key], value), key
    mask = loaded.mask_head.state_dict()
    assert torch.equal(mask['scratch.layer1_rn.weight'],
                       state['depth_head.scratch.layer1_rn.weight'])


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
    with pytest.raises(CheckpointError, match='shape'):
        convert_checkpoint('lingbot-map', tmp_path / 'big.pt', config, tmp_path / 'b')
    assert not (tmp_path / 'a').exists() and not (tmp_path / 'b').exists()


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
