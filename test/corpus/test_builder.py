"""The corpus builder on our synthetic sequences: layout, stages, resume, MANO fitting."""

import json
from pathlib import Path

import cv2
from infinihand_ros.corpus import sample_format as fmt
from infinihand_ros.corpus.adapters.synthetic import iter_synthetic
from infinihand_ros.corpus.builder import build_corpus
from infinihand_ros.corpus.builder import BuildSettings
from infinihand_ros.corpus.cli import main
from infinihand_ros.corpus.sequence import CorpusSequence
from infinihand_ros.mano.builtin import BuiltinHandModel
from infinihand_ros.synth.sample_sink import SampleSink
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
import pytest
from safetensors.numpy import load_file
import torch


@pytest.fixture(scope='module')
def synthetic_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two tiny generated sample directories."""
    root = tmp_path_factory.mktemp('synth')
    for seed in (1, 2):
        sequence = SyntheticSequence(SynthConfig(width=96, height=72, noise_sigma=0.0), seed, 4)
        with SampleSink(root / f'seq{seed}', sequence.describe()) as sink:
            for frame in sequence:
                sink.add(frame)
    return root


def _models() -> tuple[BuiltinHandModel, BuiltinHandModel]:
    return tuple(BuiltinHandModel(side, dtype=torch.float64) for side in (0, 1))


def test_synthetic_sequences_land_unchanged(synthetic_root: Path, tmp_path: Path) -> None:
    """Our own sequences keep their joints, masks and camera poses; all are Stage I and II."""
    manifest = build_corpus(iter_synthetic([synthetic_root]), tmp_path, _models(),
                            BuildSettings())
    assert len(manifest['stage_1']) == 2 and manifest['stage_2'] == manifest['stage_1']
    assert manifest['sources'] == [{'source': 'infinihand-synth', 'licence': 'Apache-2.0'}]
    written = tmp_path / manifest['stage_1'][0]
    assert written.parent.parent.name == 'shards'
    original = load_file(str(synthetic_root / 'seq1' / fmt.ANNOTATIONS_FILE))
    ours = load_file(str(written / fmt.ANNOTATIONS_FILE))
    for key in ('joints_cam', 'joints_world', 'T_world_cam', 'mano_world_transl', 'box_xyxy'):
        np.testing.assert_allclose(ours[key], original[key], atol=1e-9, err_msg=key)
    name = fmt.frame_file(2, fmt.PNG_SUFFIX)
    np.testing.assert_array_equal(
        cv2.imread(str(written / fmt.MASK_DIR / name), cv2.IMREAD_UNCHANGED),
        cv2.imread(str(synthetic_root / 'seq1' / fmt.MASK_DIR / name), cv2.IMREAD_UNCHANGED))
    meta = json.loads((written / fmt.META_FILE).read_text())
    assert meta['sequence']['source'] == 'infinihand-synth'


def test_build_resumes_and_skips_done_sequences(synthetic_root: Path, tmp_path: Path) -> None:
    """A second run leaves finished sequences untouched (the CLI prints the stage counts)."""
    assert main(['--out', str(tmp_path), '--synthetic', str(synthetic_root)]) == 0
    decision = next((tmp_path / 'decisions').glob('*.json'))
    before = decision.stat().st_mtime_ns
    assert main(['--out', str(tmp_path), '--synthetic', str(synthetic_root)]) == 0
    assert decision.stat().st_mtime_ns == before
    assert main(['--out', str(tmp_path), '--synthetic', str(tmp_path / 'none')]) == 1


def test_joints_only_sequence_gets_fitted_mano_and_masks(synthetic_root: Path,
                                                         tmp_path: Path) -> None:
    """Without MANO or masks the builder fits MANO within 2 mm and renders the masks."""
    given = next(iter_synthetic([synthetic_root / 'seq2']))
    joints_only = CorpusSequence(
        sequence_id='joints-only', source='test', licence='CC0-1.0',
        image_size=given.image_size, timestamp_ns=given.timestamp_ns, K=given.K,
        T_world_cam=None, hand_present=given.hand_present, joints_cam=given.joints_cam,
        joint_valid=given.joint_valid, mano_cam=None, read_rgb=given.read_rgb)
    manifest = build_corpus([joints_only], tmp_path, _models(), BuildSettings())
    assert manifest['stage_2'] == [] and len(manifest['stage_1']) == 1
    arrays = load_file(str(tmp_path / manifest['stage_1'][0] / fmt.ANNOTATIONS_FILE))
    assert np.nanmax(arrays['mano_fit_error_mm']) < 2.0
    assert np.all(np.isnan(arrays['T_world_cam']))
    original = load_file(str(synthetic_root / 'seq2' / fmt.ANNOTATIONS_FILE))
    visible = original['visible'].astype(bool)
    # Boxes rendered from the fitted hand contain the generator's (which lose what the scene
    # covers), up to a pixel of fitting error.
    ours, theirs = arrays['box_xyxy'][visible], original['box_xyxy'][visible]
    assert np.all(ours[:, :2] <= theirs[:, :2] + 1) and np.all(ours[:, 2:] >= theirs[:, 2:] - 1)
