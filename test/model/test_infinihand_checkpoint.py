"""Whole-model checkpoints (model/io/checkpoint.py + compose.py): round trip, no MANO data."""

from infinihand_ros.core.errors import CheckpointError
from infinihand_ros.core.hand_conventions import LEFT
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.mano.builtin import BuiltinHandModel
from infinihand_ros.model.config import load_geometry_config
from infinihand_ros.model.geometry_stream import GeometryStream
from infinihand_ros.model.hand.config import load_hand_branch_config
from infinihand_ros.model.hand.hand_branch import HandBoxes
from infinihand_ros.model.infinihand_model import InfiniHandModel
from infinihand_ros.model.io import checkpoint
from infinihand_ros.model.io.checkpoint import GEOMETRY_FILE
from infinihand_ros.model.io.checkpoint import HAND_BRANCH_FILE
from infinihand_ros.model.io.checkpoint import save_infinihand_checkpoint
from infinihand_ros.model.io.checkpoint import WEIGHTS_FILE
from infinihand_ros.model.io.compose import load_infinihand_checkpoint
import numpy as np
import pytest
from safetensors.torch import load_file
from safetensors.torch import save_file
import torch


def _forward(model: InfiniHandModel, rng: np.random.Generator) -> list[torch.Tensor]:
    """Return geometry and hand-branch outputs of one random frame with one right-hand box."""
    aggregator = model.geometry.config.aggregator
    height, width = aggregator.image_height, aggregator.image_width
    images = torch.from_numpy(rng.random((1, 1, 3, height, width), dtype='float32'))
    intrinsics = torch.tensor([[[60.0, 0.0, width / 2], [0.0, 60.0, height / 2],
                                [0.0, 0.0, 1.0]]])
    boxes = HandBoxes(torch.tensor([[20.0, 12.0, 44.0, 40.0]]), torch.zeros(1, dtype=torch.long),
                      torch.tensor([RIGHT]))
    with torch.no_grad():
        geometry = GeometryStream(model.geometry).step(images)
        hands = model.hand_branch(images[:, 0], geometry.patch_features[:, 0], intrinsics, boxes)
    return [geometry.pose_encoding, geometry.depth, geometry.hand_masks, hands.joints_cam,
            hands.landmarks_crop, hands.mano_cam.hand_pose, hands.log_depth]


def test_round_trip_keeps_configs_weights_and_outputs(model: InfiniHandModel, tmp_path) -> None:
    directory = save_infinihand_checkpoint(model, tmp_path / 'ckpt')
    assert sorted(path.name for path in directory.iterdir()) == sorted(
        (GEOMETRY_FILE, HAND_BRANCH_FILE, WEIGHTS_FILE))
    assert load_geometry_config(directory / GEOMETRY_FILE) == model.geometry.config
    assert load_hand_branch_config(directory / HAND_BRANCH_FILE) == model.hand_branch.config
    loaded, report = load_infinihand_checkpoint(directory)
    assert not loaded.training
    assert report.ok and 'hand_models' not in report.describe()
    assert report.branch('geometry').seeded == () == report.branch('hand_branch').seeded
    assert sum(report.branch('hand_branch').loaded.values()) == len(
        [key for key in model.state_dict() if key.startswith('hand_branch.')]) - 4
    expected = model.state_dict()
    assert loaded.state_dict().keys() == expected.keys()
    for key, tensor in loaded.state_dict().items():
        assert torch.equal(tensor, expected[key]), key
    for ours, theirs in zip(_forward(model, np.random.default_rng(3)),
                            _forward(loaded, np.random.default_rng(3))):
        assert torch.equal(ours, theirs)


def test_file_holds_no_hand_model_data(model: InfiniHandModel, tmp_path) -> None:
    directory = save_infinihand_checkpoint(model, tmp_path / 'ckpt')
    keys = load_file(directory / WEIGHTS_FILE).keys()
    assert not [key for key in keys if 'hand_models' in key]
    assert {key.split('.')[0] for key in keys} == {'geometry', 'hand_branch'}
    assert len(keys) == len(model.state_dict()) - 4  # 2 tensors per built-in hand model


def test_hand_models_come_from_the_caller(model: InfiniHandModel, tmp_path) -> None:
    directory = save_infinihand_checkpoint(model, tmp_path / 'ckpt')
    left, right = BuiltinHandModel(LEFT), BuiltinHandModel(RIGHT)
    loaded, _ = load_infinihand_checkpoint(directory, hand_models=(left, right))
    assert loaded.hand_branch.hand_models[0] is left and loaded.hand_branch.hand_models[1] is right


def test_missing_directory_or_file_is_a_checkpoint_error(model: InfiniHandModel,
                                                         tmp_path) -> None:
    with pytest.raises(CheckpointError, match='no such checkpoint directory'):
        load_infinihand_checkpoint(tmp_path / 'absent')
    directory = save_infinihand_checkpoint(model, tmp_path / 'ckpt')
    (directory / HAND_BRANCH_FILE).unlink()
    with pytest.raises(CheckpointError, match='hand_branch.\\* tensors without hand_branch.yaml'):
        load_infinihand_checkpoint(directory)


def test_corrupt_weights_file_is_a_checkpoint_error(model: InfiniHandModel, tmp_path) -> None:
    directory = save_infinihand_checkpoint(model, tmp_path / 'ckpt')
    (directory / WEIGHTS_FILE).write_bytes(b'\x08\x00\x00\x00\x00\x00\x00\x00{"a":')
    with pytest.raises(CheckpointError, match='not a readable safetensors file'):
        load_infinihand_checkpoint(directory)


def test_mismatched_keys_are_named(model: InfiniHandModel, tmp_path) -> None:
    directory = save_infinihand_checkpoint(model, tmp_path / 'ckpt')
    tensors = load_file(directory / WEIGHTS_FILE)
    tensors['hand_branch.fusion.bias'] = torch.zeros(3)
    tensors['hand_branch.extra'] = torch.zeros(1)
    del tensors['geometry.camera_head.token_norm.weight']
    save_file(tensors, directory / WEIGHTS_FILE)
    with pytest.raises(CheckpointError) as info:
        load_infinihand_checkpoint(directory)
    message = str(info.value)
    assert 'shape of hand_branch.fusion.bias: model [192], checkpoint [3]' in message
    assert 'unexpected: hand_branch.extra' in message
    assert 'missing: geometry.camera_head.token_norm.weight' in message


def test_hand_model_tensors_in_the_file_are_refused(model: InfiniHandModel, tmp_path) -> None:
    directory = save_infinihand_checkpoint(model, tmp_path / 'ckpt')
    tensors = load_file(directory / WEIGHTS_FILE)
    tensors['hand_branch.hand_models.1.rest_offsets'] = model.state_dict()[
        'hand_branch.hand_models.1.rest_offsets'].clone()
    save_file(tensors, directory / WEIGHTS_FILE)
    with pytest.raises(CheckpointError, match='never MANO data'):
        load_infinihand_checkpoint(directory)


def test_failed_save_leaves_nothing_and_keeps_the_old_checkpoint(model: InfiniHandModel,
                                                                 tmp_path, monkeypatch) -> None:
    def fail_half_way(tensors: dict, path, metadata: dict) -> None:
        path.write_bytes(b'half')
        raise OSError('disk full')

    old = save_infinihand_checkpoint(model, tmp_path / 'old')
    old_bytes = (old / WEIGHTS_FILE).read_bytes()
    monkeypatch.setattr(checkpoint, 'save_file', fail_half_way)
    with pytest.raises(OSError, match='disk full'):
        save_infinihand_checkpoint(model, tmp_path / 'new')
    with pytest.raises(OSError, match='disk full'):
        save_infinihand_checkpoint(model, old, overwrite=True)
    assert [path.name for path in tmp_path.iterdir()] == ['old']
    assert (old / WEIGHTS_FILE).read_bytes() == old_bytes
