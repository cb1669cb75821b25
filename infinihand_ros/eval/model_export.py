"""Export a trained checkpoint as a bundled model: half-precision storage plus the mean pose.

``python -m infinihand_ros.eval.model_export --checkpoint RUN/checkpoints/final/model --out
models/tiny_synthetic --train-sequences runs/synth_train`` reads a whole-model checkpoint,
stores its floating-point tensors as float16 (loading casts them back to the model's float32;
half the size, within float16's rounding of the weights), computes the training set's mean
articulation (``eval.baselines.mean_articulation`` over every annotated hand of the training
sequences) into ``mean_pose.json``, and writes the directory atomically. It sits above the
model's checkpoint I/O because the mean pose needs the training reader and the baseline.
"""

import argparse
import json
from pathlib import Path
import sys

from infinihand_ros.core.errors import InfiniHandError
from infinihand_ros.eval.baselines import mean_articulation
from infinihand_ros.model.io.bundled import MEAN_POSE_FILE
from infinihand_ros.model.io.checkpoint import read_checkpoint
from infinihand_ros.model.io.checkpoint import write_checkpoint
from infinihand_ros.train.sequence_reader import find_sequences
from infinihand_ros.train.sequence_reader import open_sequence
import numpy as np
import torch

#: Storage dtype of the exported floating-point tensors.
STORAGE_DTYPE = torch.float16


def training_mean_pose(sequences: list[str]) -> tuple[np.ndarray, int]:
    """Return the mean right-hand articulation (15, 3) of the sequences and the hands counted."""
    poses, sides = [], []
    for path in find_sequences(sequences):
        arrays = open_sequence(path).annotations()
        present = arrays['hand_present'].astype(bool)
        for side in (0, 1):
            poses.append(arrays['mano_cam_hand_pose'][present[:, side], side])
            sides.append(side)
    return mean_articulation(poses, sides), int(sum(len(pose) for pose in poses))


def export_model(checkpoint: str | Path, out: str | Path, sequences: list[str],
                 overwrite: bool = False) -> Path:
    """Write the bundled model of ``checkpoint`` to ``out`` (see the module docstring)."""
    contents = read_checkpoint(checkpoint)
    tensors = {key: value.to(STORAGE_DTYPE) if value.is_floating_point() else value
               for key, value in contents.tensors.items()}
    pose, count = training_mean_pose(sequences)
    mean_pose = {'hand_pose': pose.tolist(), 'hands': count,
                 'description': 'training-set mean articulation (right-hand canonical, MANO '
                                'axis-angles, 15 x 3), for the mean-pose baseline'}
    return write_checkpoint(out, tensors, contents.geometry_config, contents.hand_config,
                            source=f'exported from {Path(checkpoint)} ({STORAGE_DTYPE})',
                            overwrite=overwrite,
                            extra_files={MEAN_POSE_FILE: json.dumps(mean_pose, indent=1)
                                         .encode()})


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code."""
    parser = argparse.ArgumentParser(prog='python -m infinihand_ros.eval.model_export',
                                     description=__doc__.splitlines()[0])
    parser.add_argument('--checkpoint', required=True, help='whole-model checkpoint directory')
    parser.add_argument('--out', required=True, help='bundled model directory to write')
    parser.add_argument('--train-sequences', nargs='+', required=True,
                        help='the training sequences (for the mean pose)')
    parser.add_argument('--overwrite', action='store_true', help='replace --out')
    args = parser.parse_args(argv)
    try:
        out = export_model(args.checkpoint, args.out, args.train_sequences, args.overwrite)
    except InfiniHandError as exc:
        print(f'error: {exc}', file=sys.stderr)
        return 2
    size = sum(path.stat().st_size for path in Path(out).iterdir())
    print(f'wrote {out} ({size / 2 ** 20:.1f} MiB)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
