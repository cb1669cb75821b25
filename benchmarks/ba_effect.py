"""Measured effect of sparse BA on camera and world-space hand errors (synthetic, drifted poses).

    python benchmarks/ba_effect.py [--seconds 60] [--frames N] [--seed 1] [--json]

The estimator's raw poses are simulated as the ground truth with odometry drift (a random walk
in rotation, translation and scale of the frame-to-frame motion); depth maps are the true depth
with mild multiplicative noise. Frames stream through the binary keyframe pool; each selection
runs correspondences + BA (synchronously here, with the features of retained keyframes cached
across calls; its result applied from the next frame on) and feeds corrections back. Prints
camera ATE/RPE, the largest frame-to-frame step error and W-MPJPE/WA-MPJPE (ground-truth
camera-space joints placed by each trajectory) for BA off, BA live (what the stream published
at each frame, new results blended in over ``corrections.blend_s``) and BA final (all
corrections, interpolated), then BA call wall and CPU times and keyframes per call.
"""

import argparse
import json

import cv2
from infinihand_ros.ba.config import load_ba_config
from infinihand_ros.ba.corrections import CorrectionTrack
from infinihand_ros.ba.features import FeatureCache
from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.ba.keyframe_pool import BinaryKeyframePool
from infinihand_ros.ba.worker import plan_request
from infinihand_ros.ba.worker import run_request
from infinihand_ros.core import geometry
from infinihand_ros.eval.metrics import world_space
from infinihand_ros.synth.sequence import SynthConfig
from infinihand_ros.synth.sequence import SyntheticSequence
import numpy as np
from scipy.spatial.transform import Rotation
import torch

#: Drift of the simulated estimator per frame: rotation (rad), translation (m), log-scale.
DRIFT_ROT_RAD = 0.002
DRIFT_TRANS_M = 0.002
DRIFT_LOG_SCALE = 0.01
#: Multiplicative depth noise (fraction of the depth).
DEPTH_NOISE = 0.02
#: RPE horizon (frames): 1 s at 10 FPS.
RPE_FRAMES = 10


def drifted_poses(truth: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Return raw poses (T, 4, 4): true frame-to-frame motions with random-walk drift."""
    raw = truth.copy()
    log_scale = 0.0
    for index in range(1, len(truth)):
        motion = np.linalg.inv(truth[index - 1]) @ truth[index]
        log_scale += rng.normal(0.0, DRIFT_LOG_SCALE)
        noise = Rotation.from_rotvec(rng.normal(0.0, DRIFT_ROT_RAD, 3)).as_matrix()
        motion[:3, :3] = noise @ motion[:3, :3]
        motion[:3, 3] = np.exp(log_scale) * motion[:3, 3] + rng.normal(0.0, DRIFT_TRANS_M, 3)
        raw[index] = raw[index - 1] @ motion
    return raw


def _relative_errors(poses: np.ndarray, truth: np.ndarray, frames: int) -> np.ndarray:
    """Return the errors (T - frames, 4, 4) of the motions over ``frames`` frames."""
    rel_pred = np.linalg.inv(poses[:-frames]) @ poses[frames:]
    rel_true = np.linalg.inv(truth[:-frames]) @ truth[frames:]
    return np.linalg.inv(rel_true) @ rel_pred


def camera_errors(poses: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """Return ATE (RMSE of positions, m, no alignment), 1 s RPE (m, deg), largest step error.

    The step error is the translation error of one frame-to-frame motion (mm); its maximum
    shows jumps that the 1 s RPE averages away.
    """
    ate = np.sqrt(np.mean(np.sum((poses[:, :3, 3] - truth[:, :3, 3]) ** 2, axis=-1)))
    error = _relative_errors(poses, truth, RPE_FRAMES)
    step = _relative_errors(poses, truth, 1)
    return {'ATE_m': float(ate),
            'RPE_m': float(np.sqrt(np.mean(np.sum(error[:, :3, 3] ** 2, axis=-1)))),
            'RPE_deg': float(np.mean(geometry.rotation_angle_deg(error[:, :3, :3], np.eye(3)))),
            'step_max_mm': float(1e3 * np.max(np.linalg.norm(step[:, :3, 3], axis=-1)))}


def hand_errors(poses: np.ndarray, joints_cam: np.ndarray, joints_world: np.ndarray,
                valid: np.ndarray) -> dict[str, float]:
    """Return W-MPJPE and WA-MPJPE (mm) of true camera-space joints placed by ``poses``."""
    pred = np.einsum('tij,tshj->tshi', poses[:, :3, :3], joints_cam) + poses[:, None, None, :3, 3]
    metrics = world_space(pred, joints_world, valid)
    return {'W-MPJPE_mm': metrics['W-MPJPE'], 'WA-MPJPE_mm': metrics['WA-MPJPE']}


def run(frames: int, seed: int) -> dict:
    """Stream a sequence with BA on and return the metrics and BA call statistics."""
    config = load_ba_config()
    rng = np.random.default_rng(seed)
    sequence = SyntheticSequence(SynthConfig(), seed, frames)
    truth = np.stack([sequence.camera_pose(i).matrix() for i in range(frames)])
    raw = drifted_poses(truth, rng)
    pool = BinaryKeyframePool(config.pool.trigger, config.pool.stride)
    corrections = CorrectionTrack(config.corrections.blend_s)
    cache = FeatureCache(config.tracking)
    live = np.empty_like(raw)
    joints_cam = np.full((frames, 2, 21, 3), np.nan)
    joints_world = np.full((frames, 2, 21, 3), np.nan)
    valid = np.zeros((frames, 2), dtype=bool)
    times, cpu_times, sizes, stamps = [], [], [], []
    for index in range(frames):
        frame = sequence.frame(index)
        stamps.append(frame.timestamp_ns)
        live[index] = corrections.correct_live(frame.timestamp_ns, raw[index])
        hands = np.zeros(frame.depth.shape, dtype=bool)
        for hand in frame.hands:
            hands |= hand.mask
            joints_cam[index, hand.side] = hand.joints_cam
            joints_world[index, hand.side] = hand.joints_world
            valid[index, hand.side] = hand.visible
        noisy_depth = frame.depth * (1.0 + rng.normal(0.0, DEPTH_NOISE, frame.depth.shape))
        keyframe = KeyframeInput(index, frame.timestamp_ns, frame.rgb,
                                 noisy_depth.astype(np.float32), raw[index], frame.intrinsics,
                                 hands)
        if pool.push(index, keyframe) is None:
            continue
        selected = [entry.state for entry in pool.last_selection]
        request = plan_request(selected, corrections, pool.frame_ids())
        output = run_request(request, config, cache)
        corrections.update(output.timestamps_ns, output.T_world_cam_refined,
                           output.T_world_cam_raw)
        times.append(output.seconds)
        cpu_times.append(output.cpu_seconds)
        sizes.append(len(selected))
    final = corrections.correct(np.array(stamps), raw)
    rows = {}
    for name, poses in (('BA off', raw), ('BA live', live), ('BA final', final)):
        rows[name] = camera_errors(poses, truth) | hand_errors(poses, joints_cam, joints_world,
                                                               valid)
    return {'frames': frames, 'seed': seed, 'pool': [config.pool.trigger, config.pool.stride],
            'metrics': rows, 'ba_calls': len(times),
            'ba_seconds_median': float(np.median(times)) if times else float('nan'),
            'ba_seconds_p95': float(np.percentile(times, 95)) if times else float('nan'),
            'ba_cpu_seconds_median': float(np.median(cpu_times)) if times else float('nan'),
            'ba_cpu_seconds_p95': float(np.percentile(cpu_times, 95)) if times else float('nan'),
            'keyframes_per_call': [int(min(sizes, default=0)), int(max(sizes, default=0))]}


def print_table(result: dict) -> None:
    """Print the metrics table and the BA call statistics."""
    columns = ['ATE_m', 'RPE_m', 'RPE_deg', 'step_max_mm', 'W-MPJPE_mm', 'WA-MPJPE_mm']
    print(f"{result['frames']} frames, seed {result['seed']}, pool N={result['pool'][0]} "
          f"K={result['pool'][1]}")
    print(f"{'':10s}" + ''.join(f'{c:>13s}' for c in columns))
    for name, row in result['metrics'].items():
        print(f'{name:10s}' + ''.join(f'{row[c]:13.4f}' for c in columns))
    off, final = result['metrics']['BA off'], result['metrics']['BA final']
    live = result['metrics']['BA live']
    for metric in ('ATE_m', 'W-MPJPE_mm'):
        print(f'{metric} reduction: final {1 - final[metric] / off[metric]:.1%}, '
              f'live {1 - live[metric] / off[metric]:.1%}')
    print(f"BA calls {result['ba_calls']}: median {result['ba_seconds_median'] * 1e3:.0f} ms, "
          f"p95 {result['ba_seconds_p95'] * 1e3:.0f} ms wall (correspondences + solve); CPU time "
          f"median {result['ba_cpu_seconds_median'] * 1e3:.0f} ms, p95 "
          f"{result['ba_cpu_seconds_p95'] * 1e3:.0f} ms; keyframes per call "
          f"{result['keyframes_per_call'][0]}..{result['keyframes_per_call'][1]}")


def main() -> None:
    """Parse the arguments, run the benchmark and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seconds', type=float, default=60.0, help='sequence length at 10 FPS')
    parser.add_argument('--frames', type=int, default=None, help='override: number of frames')
    parser.add_argument('--seed', type=int, default=1)
    parser.add_argument('--json', action='store_true', help='print one JSON line')
    args = parser.parse_args()
    frames = args.frames or int(round(args.seconds * SynthConfig().fps))
    if frames < 2 * RPE_FRAMES:
        parser.error(f'need at least {2 * RPE_FRAMES} frames, got {frames}')
    torch.set_num_threads(1)
    cv2.setNumThreads(1)
    result = run(frames, args.seed)
    print(json.dumps(result) if args.json else '', end='\n' if args.json else '')
    if not args.json:
        print_table(result)


if __name__ == '__main__':
    main()
