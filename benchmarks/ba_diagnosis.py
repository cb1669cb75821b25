"""Bundle adjustment stage by stage on one sequence, each stage scored against a reference.

    python benchmarks/ba_diagnosis.py [--clip DIR | --bag [PATH]] [--cost] [--json]

``--clip``: a real clip with an SfM reference (``shared/data/real_ego/<name>``), run with the
converter's engine settings (``bag_to_dataset``'s defaults) at the clip's own rate; scores are
against the SfM trajectory (Sim(3)-aligned ATE as a share of its path, relative rotation error
between consecutive frames, first-to-last rotation error). ``--bag``: a sequence with ground
truth (default: the bundled sample bag) with the demo's settings, scored against its ground
truth the same way (path: the true path); W-MPJPE of the final trajectory's hands beside.

Stages: (1) the tracker's trajectory (what the stream had before BA, at the final metric
scale); (2) every BA call: its keyframes, tracks and inliers, its held-out check (start ->
refined cost, accepted or not), the shared lens it found, its keyframes' scores before and
after, and, rebuilt with the hand boxes alone masked, how many of its tracks lie on the
forearms and their residuals against the scene's; (3) the live trajectory; (4) the final
trajectory (every correction folded into every frame) and how far neighbouring frames'
corrections disagree. ``--cost``: the same stream again without BA, and BA's share of the
wall time (the stream and the final trajectory, BA's worker process beside it).
"""

import argparse
from dataclasses import replace
import json
from pathlib import Path
import sys
import time

from infinihand_ros.ba import costs
from infinihand_ros.ba.correspondences import build_problem
from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.ba.lie import inverse
from infinihand_ros.ba.solver import BundleAdjuster
from infinihand_ros.convert.config import load_convert_config
from infinihand_ros.convert.run import engine_config_for
from infinihand_ros.core.geometry import invert_transform
from infinihand_ros.core.geometry import rotation_angle_deg
from infinihand_ros.engine.ba_backend import box_mask
from infinihand_ros.engine.ba_backend import moving_mask
from infinihand_ros.engine.ba_in_process import InProcessBA
from infinihand_ros.engine.settings import build_engine_config
from infinihand_ros.engine.settings import OFFLINE_BA
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.eval.reference_clip import load_reference_clip
from infinihand_ros.eval.reference_clip import reference_scores
from infinihand_ros.eval.reference_clip import ReferenceClip
from infinihand_ros.eval.sequences import open_eval_sequence
from infinihand_ros.synth.sample_bag import sample_bag_path
import numpy as np

#: Frames streamed once, untimed, before ``--cost`` times the runs.
WARM_UP_FRAMES = 8

#: Where the shared real clips are, from the repository root.
REAL_EGO = Path(__file__).resolve().parents[1].parent / 'shared' / 'data' / 'real_ego'


class RecordingBA(InProcessBA):
    """The engine's in-process BA, keeping every keyframe offered and every result folded in."""

    def __init__(self, *args, **kwargs) -> None:
        """Start as ``InProcessBA``, with empty records."""
        super().__init__(*args, **kwargs)
        self.keyframes: dict[int, KeyframeInput] = {}
        self.outputs = []

    def offer(self, keyframe: KeyframeInput) -> None:
        """Keep the keyframe, then offer it."""
        self.keyframes[keyframe.frame_id] = keyframe
        super().offer(keyframe)

    def fold_in(self, track) -> list:
        """Fold results in as ``InProcessBA`` does, keeping each."""
        outputs = super().fold_in(track)
        self.outputs += outputs
        return outputs


def _world_error_mm(results: list, truth, pose_of) -> float:
    """Return the mean world-joint error (mm) of the hands placed with ``pose_of(result)``."""
    errors = []
    for row, result in enumerate(results):
        pose = pose_of(result)
        for hand in result.hands:
            if truth.visible[row, hand.side]:
                placed = pose.to_world(hand.joints_cam)
                errors.append(np.linalg.norm(placed - truth.joints_world[row, hand.side], axis=-1))
    return float(1e3 * np.mean(errors)) if errors else float('nan')


def _source(args: argparse.Namespace) -> tuple[str, ReferenceClip, list, object, object]:
    """Return (name, reference, frames (image, stamp, intrinsics), engine config, truth).

    ``truth`` is the sequence's ``GroundTruth`` (hands included), None for a real clip.
    """
    if args.bag:
        sequence = open_eval_sequence(sample_bag_path() if args.bag is True else args.bag)
        truth = sequence.truth
        centres = truth.T_world_cam[:, :3, 3]
        reference = ReferenceClip(
            sequence.name, (), truth.timestamp_ns, truth.T_world_cam, None, 0.0,
            float(np.linalg.norm(np.diff(centres, axis=0), axis=-1).sum()))
        config = build_engine_config('synthetic', OFFLINE_BA)
        return sequence.name, reference, list(sequence.frames()), config, truth
    clip = load_reference_clip(args.clip)
    frames = [(image, stamp, None) for image, stamp in clip.frames()]
    return clip.name, clip, frames, engine_config_for(load_convert_config()), None


def _fmt(scores: dict[str, float]) -> str:
    return (f"ATE {scores['ate_pct']:5.1f} % of path | rel. rotation median "
            f"{scores['rre_median_deg']:.3f} mean {scores['rre_mean_deg']:.3f} deg | "
            f"end {scores['end_deg']:.2f} deg")


def _region_split(keyframes: list[KeyframeInput], hands: dict, poses: np.ndarray,
                  config) -> dict[str, float]:
    """Rebuild a call with the hand boxes alone masked; split its tracks: forearm or scene."""
    boxed = []
    for keyframe in keyframes:
        boxed.append(replace(keyframe, hand_mask=box_mask(hands[keyframe.frame_id],
                                                          keyframe.intrinsics)))
    fixed = np.zeros(len(keyframes), dtype=bool)
    fixed[0] = True
    problem = build_problem(boxed, poses, fixed, config.tracking, config.solver)
    arms = [moving_mask(hands[k.frame_id], k.intrinsics) & ~b.hand_mask
            for k, b in zip(keyframes, boxed)]
    pixel = np.round(problem.host_xy).astype(int)
    on_arm = np.array([arms[f][y, x] for f, (x, y) in zip(problem.host, pixel)], dtype=bool)
    result = BundleAdjuster(config.solver).solve(problem)
    rotation, translation = inverse(result.T_world_cam[:, :3, :3], result.T_world_cam[:, :3, 3])
    state = costs.PoseState(rotation, translation, result.inv_depth, result.lens)
    rays = costs.host_rays(problem.intrinsics, problem.host, problem.host_xy, result.lens)
    error = np.linalg.norm(costs.reprojection(
        state, rays, problem.host, problem.obs_track, problem.obs_frame, problem.obs_xy,
        problem.intrinsics, False).residual, axis=-1)
    arm_obs = on_arm[problem.obs_track]

    def median(values: np.ndarray) -> float:
        return float(np.median(values)) if len(values) else float('nan')

    return {'tracks': int(len(on_arm)), 'arm_tracks': int(on_arm.sum()),
            'scene_median_px': median(error[~arm_obs]), 'arm_median_px': median(error[arm_obs])}


def _stream_without_ba(config, frames: list) -> None:
    """Stream the frames with BA off, to its final trajectory."""
    with StreamingEngine(replace(config, bundle_adjustment=None)) as engine:
        results = []
        for image, stamp, intrinsics in frames:
            results += engine.push(image, stamp, intrinsics)
        engine.refined(results + engine.flush())


def run(args: argparse.Namespace) -> dict:
    """Stream the sequence with BA on, recording every stage; return the report."""
    name, reference, frames, config, truth = _source(args)
    if args.cost:  # untimed, so neither timed run pays the first use of the model's kernels
        _stream_without_ba(config, frames[:WARM_UP_FRAMES])
    backend = RecordingBA(config.bundle_adjustment, config.pose_track.capacity)
    start = time.perf_counter()
    with StreamingEngine(config, ba_backend=backend) as engine:
        live = []
        for image, stamp, intrinsics in frames:
            live += engine.push(image, stamp, intrinsics)
        live += engine.flush()
        final = engine.refined(live)
        corrections = engine.pose_track.corrections.corrections(
            np.array([r.timestamp_ns for r in live]))
    seconds = time.perf_counter() - start
    tracker = np.stack([(r.raw_camera_pose or r.camera_pose).matrix() for r in final])
    report = {'sequence': name, 'frames': len(live), 'seconds': round(seconds, 1),
              'tracker': reference_scores(tracker, reference),
              'live': reference_scores(np.stack([r.camera_pose.matrix() for r in live]),
                                       reference),
              'final': reference_scores(np.stack([r.camera_pose.matrix() for r in final]),
                                        reference),
              'predicted_focal_px': float(np.median([r.intrinsics.fx for r in live]))}
    if truth is not None:
        report['w_mpjpe_mm'] = {
            'tracker': _world_error_mm(final, truth, lambda r: r.raw_camera_pose or r.camera_pose),
            'final': _world_error_mm(final, truth, lambda r: r.camera_pose)}
    if reference.intrinsics is not None:
        report['reference_focal_px'] = reference.intrinsics.fx
        report['reference_k1'] = reference.k1
    steps = invert_transform(corrections[:-1]) @ corrections[1:]
    report['correction_step_deg'] = {
        'median': float(np.median(rotation_angle_deg(steps[:, :3, :3], np.eye(3)))),
        'max': float(np.max(rotation_angle_deg(steps[:, :3, :3], np.eye(3))))}
    hands = {r.frame_index: r.hands for r in live}
    calls = []
    for output in backend.outputs:
        ids = output.frame_ids
        keyframes = [backend.keyframes[int(i)] for i in ids]
        call = {'frames': [int(ids[0]), int(ids[-1]), len(ids)], 'tracks': output.num_tracks,
                'observations': output.num_observations, 'inliers': output.num_inliers,
                'held_out_costs': [float(c) for c in output.held_out_costs],
                'accepted': output.accepted, 'focal_px': output.focal_px, 'k1': output.k1,
                'seconds': output.seconds,
                'start': reference_scores(output.T_world_cam_raw, reference, ids),
                'refined': reference_scores(output.T_world_cam_refined, reference, ids)}
        call['regions'] = _region_split(keyframes, hands, output.T_world_cam_raw,
                                        config.bundle_adjustment)
        calls.append(call)
    report['calls'] = calls
    if args.cost:
        start = time.perf_counter()
        _stream_without_ba(config, frames)
        without = time.perf_counter() - start
        report['seconds_without_ba'] = round(without, 1)
        report['ba_share_pct'] = round(100.0 * (seconds - without) / seconds, 1)
    return report


def _print(report: dict) -> None:
    print(f"{report['sequence']}: {report['frames']} frames in {report['seconds']} s; "
          f"predicted focal {report['predicted_focal_px']:.1f} px"
          + (f" (reference {report['reference_focal_px']:.1f} px, k1 "
             f"{report['reference_k1']:.3f})" if 'reference_focal_px' in report else ''))
    print(f'  1 tracker  {_fmt(report["tracker"])}')
    for index, call in enumerate(report['calls']):
        first, last, count = call['frames']
        regions = call['regions']
        verdict = 'accepted' if call['accepted'] else 'REJECTED'
        print(f'  2 BA call {index}: frames {first}..{last} ({count} keyframes), '
              f"{call['tracks']} tracks, {call['inliers']}/{call['observations']} inliers, "
              f"{call['seconds']:.2f} s; held-out cost {call['held_out_costs'][0]:.3f} -> "
              f"{call['held_out_costs'][1]:.3f} px^2 ({verdict}); "
              f"lens focal {call['focal_px']:.1f} px, k1 {call['k1']:.3f}")
        print(f"      start    {_fmt(call['start'])}")
        print(f"      refined  {_fmt(call['refined'])}")
        print(f"      boxes-only mask: {regions['arm_tracks']} of {regions['tracks']} tracks on "
              f"forearms; residual median scene {regions['scene_median_px']:.2f} px, forearms "
              f"{regions['arm_median_px']:.2f} px")
    print(f"  3 live     {_fmt(report['live'])}")
    print(f"  4 final    {_fmt(report['final'])}")
    steps = report['correction_step_deg']
    print(f"    correction change between neighbouring frames: median {steps['median']:.3f}, "
          f"max {steps['max']:.3f} deg")
    if 'ba_share_pct' in report:
        print(f"  wall time {report['seconds']} s with BA, {report['seconds_without_ba']} s "
              f"without: BA's share {report['ba_share_pct']} %")
    if 'w_mpjpe_mm' in report:
        print(f"  hands in the world (W-MPJPE): tracker {report['w_mpjpe_mm']['tracker']:.1f} mm, "
              f"final {report['w_mpjpe_mm']['final']:.1f} mm")


def main(argv: list[str] | None = None) -> int:
    """Run the diagnosis and print it (or its JSON)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    source = parser.add_mutually_exclusive_group()
    source.add_argument('--clip', type=Path, default=REAL_EGO / 'ego4d_counter',
                        help='real clip folder with sfm_poses.json (default: %(default)s)')
    source.add_argument('--bag', nargs='?', const=True, type=Path,
                        help='a sequence with ground truth instead (default: the sample bag)')
    parser.add_argument('--cost', action='store_true',
                        help="also run without BA and print BA's share of the wall time")
    parser.add_argument('--json', action='store_true', help='print the report as JSON')
    args = parser.parse_args(argv)
    report = run(args)
    if args.json:
        print(json.dumps(report, indent=1))
    else:
        _print(report)
    return 0


if __name__ == '__main__':
    sys.exit(main())
