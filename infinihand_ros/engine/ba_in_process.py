"""Sparse bundle adjustment beside the stream, in this process's care (paper Sec. 3.3).

Keyframes enter ``KeyframeBA`` (the binary keyframe pool and a ``BundleAdjustmentWorker``,
which runs BA in its own process, so its thread settings, CPU priority and crashes stay there)
and the stream goes on at once. Finished BA calls are handed to the pose track
(``engine/pose_track.py``), which applies them as corrections; nothing here places hands or
changes results. The track's correction history is pruned to what the pool and the track can
still query, so memory and time stay bounded on an unbounded stream; the frames of failed BA
calls are remembered (as many as the pose track holds) so their results can say so. Closing or
resetting never waits long for BA: queued calls are dropped and a running one gets
``STOP_WAIT_S`` (a node stopped with Ctrl-C exits promptly); ``settle`` first to get every
result. With ``episode.enabled`` (offline runs) the episode's keyframes are kept too, and
``settle`` ends with one refinement of the whole episode (``ba/episode.py``), folded into the
pose track where it is accepted.
"""

import logging
from typing import Final

from infinihand_ros.ba.config import BAConfig
from infinihand_ros.ba.episode import EpisodeKeyframes
from infinihand_ros.ba.episode import EpisodeRefinement
from infinihand_ros.ba.episode import refine_episode
from infinihand_ros.ba.keyframe import BAOutput
from infinihand_ros.ba.keyframe import KeyframeInput
from infinihand_ros.ba.keyframe import StreamLens
from infinihand_ros.ba.keyframe_ba import KeyframeBA
from infinihand_ros.ba.worker import BAWorkerError
from infinihand_ros.ba.worker import BundleAdjustmentWorker
from infinihand_ros.ba.worker import FAILED_FRAMES_KEPT
from infinihand_ros.engine.ba_backend import prune_corrections
from infinihand_ros.engine.pose_track import PoseTrack
import numpy as np

logger = logging.getLogger(__name__)

#: On close and reset, seconds the running BA call gets before its process is killed (queued
#: calls are dropped at once: their results could only reach a stream that has ended).
STOP_WAIT_S: Final = 0.5


class InProcessBA:
    """The ``BABackend`` that runs BA in a background worker process of the engine's own."""

    def __init__(self, config: BAConfig, failed_frames_kept: int = FAILED_FRAMES_KEPT) -> None:
        """Start the BA worker with an empty pool.

        Args:
            config: the BA settings.
            failed_frames_kept: frames of failed calls remembered, the newest (the engine's
                ``pose_track.capacity``: every frame whose pose it can still give).

        """
        self.config = config
        self.failed_frames_kept = failed_frames_kept
        self._start()

    def _start(self) -> None:
        """Start a new pool and worker."""
        self.ba = KeyframeBA(self.config, BundleAdjustmentWorker(
            self.config, failed_frames_kept=self.failed_frames_kept))
        self.calls_done = 0
        episode = self.config.episode
        self.episode = EpisodeKeyframes(episode.max_keyframes) if episode.enabled else None
        self.episode_result: EpisodeRefinement | None = None
        self._lens: StreamLens | None = None  # the accepted calls' lens
        self._episode_span: tuple[int, int] | None = None  # frames the episode refined

    def offer(self, keyframe: KeyframeInput) -> None:
        """Feed a keyframe to the pool; a triggered selection goes to the worker (no wait)."""
        if self.episode is not None:
            self.episode.add(keyframe)
        self.ba.add(keyframe)

    def fold_in(self, track: PoseTrack) -> list[BAOutput]:
        """Hand finished BA calls to ``track``; prune corrections nobody can query any more.

        Returns:
            The calls handed over, oldest first (for diagnostics).

        """
        outputs = self.ba.worker.poll()
        for output in outputs:
            track.update_corrections(output.timestamps_ns, output.T_world_cam_refined,
                                     output.T_world_cam_raw, output.scale)
            self.calls_done += 1
            if output.accepted:
                self._lens = (StreamLens(output.focal_px, output.k1, 1) if self._lens is None
                              else self._lens.updated(output.focal_px, output.k1))
        prune_corrections(track, self.ba.pooled_stamps())
        return outputs

    def settle(self, track: PoseTrack, timeout_s: float | None = None) -> bool:
        """Refine the pool's tail, wait for every queued BA call, hand the results to ``track``.

        For the end of a stream (offline runs): see ``KeyframeBA.finish``. With
        ``episode.enabled`` the whole episode is then refined once (``refine_episode``).

        Returns:
            True when BA finished everything it was given, False when ``timeout_s`` ran out.

        """
        try:
            self.ba.finish()
        except BAWorkerError as exc:  # its failed calls are already counted and flagged
            logger.warning("BA: the stream's last keyframes stay unrefined (%s)", exc)
        idle = self.ba.worker.wait_idle(timeout_s)
        self.fold_in(track)
        if self.episode is not None and self.episode_result is None:
            self.episode_result = self._refine_episode(track)
        return idle

    def _refine_episode(self, track: PoseTrack) -> EpisodeRefinement | None:
        """Refine the kept keyframes still in ``track`` from its final poses; fold in if used."""
        kept, T_start, T_raw = [], [], []
        for keyframe in self.episode.keyframes():
            try:
                best = track.best(keyframe.frame_id, live=False)
            except KeyError:  # no longer in the track: its pose is written as it is
                continue
            kept.append(keyframe.at_scale(track.scale))
            T_start.append(best.camera_pose.matrix())
            T_raw.append(best.scaled_pose.matrix())
        if len(kept) < 2:
            return None
        refinement = refine_episode(kept, np.stack(T_start), self._lens, self.config)
        if refinement.accepted:
            track.update_corrections(refinement.timestamps_ns, refinement.T_refined,
                                     np.stack(T_raw), track.scale)
            self._episode_span = (kept[0].frame_id, kept[-1].frame_id)
        return refinement

    def episode_refined(self) -> bool:
        """Return whether the whole-episode refinement is in the track's poses."""
        return self.episode_result is not None and self.episode_result.accepted

    def failed_frames(self) -> frozenset[int]:
        """Return the frames whose last BA call failed (solver error, BA process died).

        The whole-episode refinement, where accepted, replaces every correction between its
        first and last keyframes: no frame there lacks a refinement.
        """
        failed = self.ba.worker.failed_frame_ids
        if self._episode_span is None:
            return failed
        first, last = self._episode_span
        return frozenset(frame for frame in failed if not first <= frame <= last)

    def statistics(self) -> dict[str, object]:
        """Return the BA worker's state, its counters and last error, and the results folded in.

        ``state`` is 'idle', 'running', 'stopped' or 'failed' (the BA process kept dying;
        the stream goes on with unrefined poses).
        """
        worker = self.ba.worker.statistics
        return {'state': str(worker.state), 'submitted': worker.submitted, 'done': worker.done,
                'dropped': worker.dropped, 'failed': worker.failed, 'rejected': worker.rejected,
                'callback_errors': worker.callback_errors, 'last_error': worker.last_error,
                'folded_in': self.calls_done,
                'episode': None if self.episode_result is None else self.episode_result.to_dict()}

    def reset(self) -> None:
        """Stop the worker (``close``) and start an empty pool and a new one."""
        self.close()
        self._start()

    def close(self) -> None:
        """Drop queued BA calls, give the running one ``STOP_WAIT_S``, stop the worker.

        Results not handed over by then are lost: ``settle`` first to get every one.
        """
        self.ba.worker.close(STOP_WAIT_S)
