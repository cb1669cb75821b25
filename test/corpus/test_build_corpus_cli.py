"""``build_corpus`` with the new inputs: a dataset flag, and pseudo-labels from real photos."""

import json
from pathlib import Path

from dataset_layouts import ho3d
from infinihand_ros.core.hand_conventions import RIGHT
from infinihand_ros.corpus.cli import main
from infinihand_ros.synth.known_tracks import known_track
import numpy as np
import pytest

STILLS = Path(__file__).resolve().parents[3] / 'shared' / 'data' / 'real_hands_stills'


def test_dataset_flag_builds_uncleaned_with_keypoints_none(tmp_path: Path) -> None:
    """``--ho3d DIR --keypoints none`` writes the sequence and records it as not cleaned."""
    joints = known_track(np.random.default_rng(2), RIGHT, 3).joints
    root = ho3d(tmp_path / 'ho3d', joints)
    assert main(['--out', str(tmp_path / 'c'), '--ho3d', str(root), '--keypoints', 'none']) == 0
    manifest = json.loads((tmp_path / 'c' / 'manifest.json').read_text())
    assert manifest['sources'][0]['source'] == 'ho3d'
    assert manifest['sequences'][0]['reason'] == 'not cleaned (no 2D source)'
    assert main(['--out', str(tmp_path / 'd'), '--from-bags', str(root),
                 '--keypoints', 'none']) == 1


def test_from_bags_pseudo_labels_real_photos_and_cleans_them(tmp_path: Path) -> None:
    """Real photos become a Stage I sequence with confidences, cleaned against MediaPipe."""
    if not STILLS.is_dir():
        pytest.skip(f'real hand photos not found at {STILLS}')
    pytest.importorskip('mediapipe')
    assert main(['--out', str(tmp_path), '--from-bags', str(STILLS)]) == 0
    record = json.loads((tmp_path / 'manifest.json').read_text())['sequences'][0]
    assert record['source'] == 'pseudo-labels' and record['mano_fitted']
    assert not record['camera_trajectory']
    evaluated = sum(hand['evaluated'] for hand in record['hands'].values())
    assert evaluated >= 20
    assert record['decision'] in ('keep', 'review', 'discard')
