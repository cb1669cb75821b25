"""The converter on real head-mounted clips: camera against SfM, hands against MediaPipe.

    python benchmarks/real_ego.py [--clips DIR...] [--no-ba] [--json]

Each clip of ``../shared/data/real_ego`` (frames, a pycolmap SfM trajectory and lens, MediaPipe
Hands alone on every frame) goes through ``bag_to_dataset``'s engine settings at its own rate,
no intrinsics given, and the final trajectory (what the converter writes) is scored:
- camera: Sim(3)-aligned ATE as a share of the SfM path, relative rotation error between
  consecutive frames, and the written focal length against SfM's;
- hands: MediaPipe alone's hands (its unmirrored handedness) found on the same side and on
  either side; the written world joints projected through the written camera pose and
  intrinsics against MediaPipe's landmarks (per hand the median joint distance over the size of
  MediaPipe's landmark box; median and 90th percentile over hands); written hands where
  MediaPipe alone finds none on that side;
- MediaPipe alone's labels checked against the arm's side of entry (where it decides a side):
  how many it decides, how many MediaPipe alone labels that way, and how many of ours are on
  that side;
- the converter's accounting of the hands its own MediaPipe found: written, or dropped for a
  named reason (``convert/hand_accounting.py``).
- cost: the engine's wall time from the first frame to the final trajectory (BA and the
  whole-episode refinement included; compare with ``--no-ba``), and the whole-episode
  refinement's verdict.
"""

import argparse
from dataclasses import asdict
from dataclasses import replace
import json
from pathlib import Path
import time

from infinihand_ros.convert.config import load_convert_config
from infinihand_ros.convert.hand_accounting import account_hands
from infinihand_ros.convert.lerobot_features import frame_values
from infinihand_ros.convert.lerobot_features import HAND_VALID
from infinihand_ros.convert.run import engine_config_for
from infinihand_ros.engine.streaming_engine import StreamingEngine
from infinihand_ros.eval.reference_clip import arm_scores
from infinihand_ros.eval.reference_clip import hand_scores
from infinihand_ros.eval.reference_clip import load_reference_clip
from infinihand_ros.eval.reference_clip import mediapipe_hands
from infinihand_ros.eval.reference_clip import mediapipe_labelled
from infinihand_ros.eval.reference_clip import reference_scores
import numpy as np
from records import add_record_option
from records import Figure
from records import write_record

REAL_EGO = Path(__file__).resolve().parents[2] / 'shared' / 'data' / 'real_ego'


def run(folder: Path, with_ba: bool) -> dict:
    """Convert one clip's frames with the converter's engine settings; return its scores."""
    clip = load_reference_clip(folder)
    config = engine_config_for(load_convert_config())
    if not with_ba:
        config = replace(config, bundle_adjustment=None)
    frames = list(clip.frames())
    with StreamingEngine(config) as engine:
        source_before = engine.statistics['hands']
        start = time.perf_counter()
        live = []
        for image, stamp in frames:
            live += engine.push(image, stamp, None)
        final = engine.refined(live + engine.flush())
        source_after = engine.statistics['hands']
        seconds = time.perf_counter() - start
        ba = engine.statistics['ba']
    focal = float(np.median([result.intrinsics.fx for result in final]))
    report = {'clip': clip.name, 'frames': len(final),
              'camera': reference_scores(np.stack([r.camera_pose.matrix() for r in final]),
                                         clip),
              'focal_px': focal, 'sfm_focal_px': clip.intrinsics.fx,
              'focal_error_pct': 100.0 * (focal / clip.intrinsics.fx - 1.0),
              'seconds': seconds, 'episode': None if ba is None else ba.get('episode')}
    report['hands'] = hand_scores(final, mediapipe_hands(folder))
    report['arm'] = arm_scores(final, mediapipe_labelled(folder))
    values = [frame_values(result, 0.0) for result in final]
    written = int(sum(columns[HAND_VALID].sum() for columns, _ in values))
    report['accounting'] = asdict(account_hands(source_before, source_after, written,
                                                [reasons for _, reasons in values]))
    return report


def record_figures(reports: list[dict], with_ba: bool) -> list[Figure]:
    """Return each clip's camera and hand scores as record figures."""
    figures = []
    for report in reports:
        label = f"{report['clip']} (BA {'on' if with_ba else 'off'})"
        figures += [
            Figure(f'{label}: camera ATE, share of the SfM path',
                   report['camera']['ate_pct'], '%'),
            Figure(f'{label}: focal length error against SfM', report['focal_error_pct'], '%'),
            Figure(f"{label}: MediaPipe's hands found on the same side",
                   100.0 * report['hands']['found_same_side'], '%'),
            Figure(f'{label}: reprojected joints, median (share of the hand box)',
                   report['hands']['reprojection_median'], '')]
    return figures


def main() -> None:
    """Print one row per clip."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--clips', type=Path, nargs='+',
                        default=sorted(p for p in REAL_EGO.iterdir() if p.is_dir())
                        if REAL_EGO.is_dir() else [])
    parser.add_argument('--no-ba', action='store_true', help='bundle adjustment off')
    parser.add_argument('--json', action='store_true')
    add_record_option(parser)
    args = parser.parse_args()
    if not args.clips:
        raise SystemExit(f'no clips: {REAL_EGO} is absent; pass --clips')
    reports = [run(folder, not args.no_ba) for folder in args.clips]
    write_record(args.record, 'real_ego', record_figures(reports, not args.no_ba))
    if args.json:
        print(json.dumps(reports))
        return
    print(f"bag_to_dataset settings (BA {'off' if args.no_ba else 'on'}), final trajectory, "
          'no intrinsics given')
    print('| clip | ATE (% path) | rel. rot. median (deg) | focal (px) vs SfM | MediaPipe hands | '
          'found same side | either side | reprojection median / p90 (box) | not in MediaPipe | '
          'engine (s) |')
    print('|---|---|---|---|---|---|---|---|---|---|')
    for r in reports:
        c, h = r['camera'], r['hands']
        print(f"| {r['clip']} | {c['ate_pct']:.1f} | {c['rre_median_deg']:.3f} | "
              f"{r['focal_px']:.0f} vs {r['sfm_focal_px']:.0f} ({r['focal_error_pct']:+.1f} %) | "
              f"{h['mediapipe_hands']} | {100 * h['found_same_side']:.0f} % | "
              f"{100 * h['found_either_side']:.0f} % | {h['reprojection_median']:.3f} / "
              f"{h['reprojection_p90']:.3f} | {h['not_in_mediapipe']} | {r['seconds']:.1f} |")
    for r in reports:
        if r['episode']:
            e = r['episode']
            print(f"{r['clip']}: whole-episode refinement "
                  f"{'accepted' if e['accepted'] else 'refused'} ({e['reason']}); largest "
                  f"keyframe move {e['max_move_m']:.4f} m, bound {e['move_bound_m']:.4f} m; "
                  f"{e['seconds']:.2f} s")
    print()
    print('| clip | MediaPipe alone: arm decides | MediaPipe labels it so | ours on that side | '
          'frames MediaPipe labels two hands alike | our MediaPipe: found | written | dropped |')
    print('|---|---|---|---|---|---|---|---|')
    for r in reports:
        a, n = r['arm'], r['accounting']
        dropped = ', '.join(f'{count} {reason}' for reason, count in n['dropped'].items())
        print(f"| {r['clip']} | {a['arm_decided']} | {a['reference_with_arm']} | "
              f"{a['ours_with_arm']} | {a['reference_label_twice']} | {n['found']} | "
              f"{n['written']} | {dropped or 'none'} |")


if __name__ == '__main__':
    main()
