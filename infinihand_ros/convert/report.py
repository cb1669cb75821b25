"""Per-episode conversion reports and the summary table printed at the end of a run."""

from collections import Counter
from dataclasses import asdict
from dataclasses import dataclass
from dataclasses import field
from typing import Any, Final

from infinihand_ros.convert.hand_accounting import HandAccounting

CONVERTED: Final = 'converted'
FAILED: Final = 'failed'
SKIPPED: Final = 'already in dataset'


@dataclass
class EpisodeReport:
    """What happened to one episode (one input, or one time window of it).

    Attributes:
        source: the input's path (with ``#window`` when inputs are split).
        status: 'converted', 'failed' or 'already in dataset'.
        error: why it failed ('' otherwise).
        episode_index: its index in the dataset (-1 unless converted).
        frames_in: source frames read.
        frames_used: distinct source frames run through the engine.
        frames_out: output frames at the dataset's fps.
        skipped: reason -> dropped source frames.
        warnings: reason -> frames kept despite a problem.
        hands_valid: side -> output frames with a valid hand.
        hands_invalid: side -> {reason -> output frames} for frames without a valid hand.
        hands_found: the hands the hand source found in the frames used, per frame used (not
            per output frame): how many were written, and how many dropped for each reason;
            they add up.
        camera_tracking: output frames whose camera pose was measured in the image
            ('tracked'), came from the network's motion ('predicted'), or where the camera
            track restarted ('reinitialised': a discontinuity).
        ba_failed_frames: output frames whose last bundle-adjustment call failed
            (``camera.flags`` ba_failed: their poses lack that refinement).
        episode_refined_frames: output frames whose pose carries the whole-episode refinement
            (``camera.flags`` episode_refined; its verdict is ``bundle_adjustment['episode']``).
        source_gaps: output frames farther than ``max_source_gap_s`` from any source frame.
        max_source_gap_s: the largest distance of an output frame to its source frame.
        metric_scale: the engine's final metric-scale estimate.
        bundle_adjustment: the engine's BA statistics (None when BA is off).
        seconds: wall time of the episode.

    """

    source: str
    status: str = CONVERTED
    error: str = ''
    episode_index: int = -1
    frames_in: int = 0
    frames_used: int = 0
    frames_out: int = 0
    skipped: dict[str, int] = field(default_factory=dict)
    warnings: dict[str, int] = field(default_factory=dict)
    hands_valid: dict[str, int] = field(default_factory=dict)
    hands_invalid: dict[str, dict[str, int]] = field(default_factory=dict)
    hands_found: HandAccounting = field(default_factory=HandAccounting)
    camera_tracking: dict[str, int] = field(default_factory=dict)
    ba_failed_frames: int = 0
    episode_refined_frames: int = 0
    source_gaps: int = 0
    max_source_gap_s: float = 0.0
    metric_scale: float = 1.0
    bundle_adjustment: dict[str, Any] | None = None
    seconds: float = 0.0

    @property
    def frames_per_s(self) -> float:
        """Return output frames per wall second."""
        return self.frames_out / self.seconds if self.seconds > 0 else 0.0

    def to_dict(self) -> dict[str, Any]:
        """Return the report as JSON-ready data."""
        data = asdict(self)
        data['frames_per_s'] = self.frames_per_s
        return data

    def lines(self) -> list[str]:
        """Return the report as readable lines."""
        if self.status != CONVERTED:
            return [f'{self.source}: {self.status}' + (f' ({self.error})' if self.error else '')]
        out = [f'{self.source}: episode {self.episode_index}, frames in {self.frames_in} / used '
               f'{self.frames_used} / out {self.frames_out}, {self.frames_per_s:.1f} frames/s, '
               f'metric scale {self.metric_scale:.4g}']
        out.append('  valid hands: ' + ', '.join(f'{side} {count}'
                                                 for side, count in self.hands_valid.items()))
        for side, reasons in self.hands_invalid.items():
            out += [f'  {side} hand invalid in {count} frames: {reason}'
                    for reason, count in reasons.items()]
        out.append(f'  {self.hands_found.line()} (frames used)')
        if self.camera_tracking:
            out.append('  camera pose: ' + ', '.join(
                f'{state} {count}' for state, count in self.camera_tracking.items()))
        out += [f'  skipped {count} frames: {reason}' for reason, count in self.skipped.items()]
        out += [f'  warning ({count} frames): {reason}' for reason, count in self.warnings.items()]
        if self.source_gaps:
            out.append(f'  {self.source_gaps} output frames are more than the allowed gap from '
                       f'a source frame (largest {self.max_source_gap_s:.3f} s)')
        if self.bundle_adjustment is not None:
            ba = self.bundle_adjustment
            out.append(f"  bundle adjustment: {ba.get('done', 0)} runs done, "
                       f"{ba.get('failed', 0)} failed, {ba.get('dropped', 0)} dropped; "
                       f'{self.ba_failed_frames} output frames flagged ba_failed')
            episode = ba.get('episode')
            if episode:
                verdict = 'accepted' if episode['accepted'] else 'refused'
                out.append(f"  whole-episode refinement over {episode['keyframes']} keyframes "
                           f'{verdict} ({self.episode_refined_frames} output frames): '
                           f"{episode['reason']}; largest keyframe move "
                           f"{episode['max_move_m']:.4f} m (bound "
                           f"{episode['move_bound_m']:.4f} m)")
        return out


def summary_table(reports: list[EpisodeReport]) -> str:
    """Return a fixed-width table of every episode and a totals line."""
    header = f"{'status':<19} {'episode':>7} {'in':>7} {'out':>7} {'skip':>6} {'fps':>7}  source"
    rows = [header, '-' * len(header)]
    for report in reports:
        episode = str(report.episode_index) if report.episode_index >= 0 else '-'
        rows.append(f'{report.status:<19} {episode:>7} {report.frames_in:>7} '
                    f'{report.frames_out:>7} {sum(report.skipped.values()):>6} '
                    f'{report.frames_per_s:>7.1f}  {report.source}')
    statuses = Counter(report.status for report in reports)
    rows.append(', '.join(f'{count} {status}' for status, count in sorted(statuses.items()))
                + f'; {sum(r.frames_out for r in reports if r.status == CONVERTED)} frames '
                  'written')
    return '\n'.join(rows)
