"""Streaming interface of the geometry branch: frames in, per-frame geometry out.

``GeometryStream.step(images, keyframe)`` takes one frame or a window of frames (B, S, 3, H, W)
RGB in [0, 1] and returns a ``GeometryOutput`` for every frame of the call; B >= 1 sequences
advance in lockstep (a training batch of clips; keep B until ``reset()``). The first
``memory.anchor_frames`` frames of a sequence are anchors (stored whatever their flag; pass them
in one call to match the paper, which processes them together). Later frames are stored when
their keyframe flag is set. A window of frames in one call gives the same outputs as its frames
one by one (causal attention). ``reset()`` starts a new sequence. A block whose outputs are not
finite is not committed: ``step`` raises ``ModelOutputError`` and the stream stays as it was.
"""

from collections.abc import Sequence
from dataclasses import fields

from infinihand_ros.core.errors import InputError
from infinihand_ros.core.errors import ModelOutputError
from infinihand_ros.model.aggregator import AggregatorOutput
from infinihand_ros.model.geometry_model import DenseInput
from infinihand_ros.model.geometry_model import GeometryModel
from infinihand_ros.model.geometry_model import GeometryOutput
from infinihand_ros.model.streaming_memory import FrameSchedule
from infinihand_ros.model.streaming_memory import KVMemory
import torch


def _concat_outputs(first: GeometryOutput, second: GeometryOutput) -> GeometryOutput:
    """Join two consecutive blocks' outputs along the frame axis."""
    values = {}
    for item in fields(GeometryOutput):
        a, b = getattr(first, item.name), getattr(second, item.name)
        if a is None:
            values[item.name] = None
        elif isinstance(a, torch.Tensor):
            values[item.name] = torch.cat((a, b), dim=1)
        elif isinstance(a, tuple):
            values[item.name] = tuple(torch.cat(pair, dim=1) for pair in zip(a, b))
        elif isinstance(a, DenseInput):
            tokens = AggregatorOutput(tuple(torch.cat(pair, dim=1) for pair in zip(
                a.tokens.layers, b.tokens.layers)), a.tokens.patch_start, a.tokens.grid)
            values[item.name] = DenseInput(tokens, a.image_size)
        else:
            values[item.name] = a
    return GeometryOutput(**values)


def _check_finite(output: GeometryOutput) -> None:
    """Raise ModelOutputError naming the first output with NaN or infinite values."""
    for name in ('pose_encoding', 'depth', 'depth_conf', 'hand_masks', 'patch_features'):
        value = getattr(output, name)
        if value is not None and not bool(torch.isfinite(value).all()):
            raise ModelOutputError(f'geometry branch: its {name} output is not finite; the '
                                   'weights are broken (check the checkpoint), the frame was '
                                   'not added to the stream')


class GeometryStream:
    """Holds one sequence's memories around a ``GeometryModel``."""

    def __init__(self, model: GeometryModel) -> None:
        """Wrap ``model``; the stream starts empty."""
        self.model = model
        self.schedule = FrameSchedule(model.config.memory.anchor_frames)
        self.aggregator_memory, self.camera_memory = model.new_memories()

    def reset(self) -> None:
        """Forget the sequence (memories and frame counters)."""
        self.schedule.reset()
        self.aggregator_memory.reset()
        self.camera_memory.reset()

    @property
    def memories(self) -> tuple[KVMemory, KVMemory]:
        """Return the (aggregator, camera head) memories, e.g. to inspect cached tokens."""
        return self.aggregator_memory, self.camera_memory

    def step(self, images: torch.Tensor, keyframe: bool | Sequence[bool] = True,
             cpu_bf16: bool = False, masks: bool = True, depth: bool = True) -> GeometryOutput:
        """Process one or more frames and return their outputs.

        Args:
            images: (B, S, 3, H, W) float RGB in [0, 1] on the model's device, B >= 1; H and W
                multiples of the patch size (the configured size is the one the weights expect).
            keyframe: one flag for all S frames, or one per frame.
            cpu_bf16: bf16 aggregator on the CPU (``GeometryModel.forward``); False: float32.
            masks: run the mask head (False: ``hand_masks`` is None).
            depth: run the depth head (False: ``depth`` is None; ``GeometryModel.frame_depth``
                computes a frame's depth from ``dense_input`` later).

        Raises:
            InputError: for a wrong shape or dtype, or a flag list of the wrong length.

        """
        flags = self._check(images, keyframe)
        remaining = self.schedule.anchors_remaining
        if 0 < remaining < len(flags):
            head = self.step(images[:, :remaining], flags[:remaining], cpu_bf16, masks, depth)
            return _concat_outputs(head, self.step(images[:, remaining:], flags[remaining:],
                                                   cpu_bf16, masks, depth))
        plan = self.schedule.plan(flags)
        try:
            output = self.model(images, plan, self.aggregator_memory, self.camera_memory,
                                cpu_bf16, masks, depth)
            _check_finite(output)
        except BaseException:
            for memory in self.memories:
                memory.abort()
            raise
        for memory in self.memories:
            memory.commit()
        self.schedule.commit(plan)
        return output

    def _check(self, images: torch.Tensor, keyframe: bool | Sequence[bool]) -> list[bool]:
        """Validate the input and return one keyframe flag per frame."""
        patch = self.model.config.aggregator.patch_size
        if (not isinstance(images, torch.Tensor) or images.dim() != 5 or images.shape[0] < 1
                or images.shape[2] != 3 or not images.is_floating_point()):
            got = tuple(images.shape) if isinstance(images, torch.Tensor) else type(images)
            raise InputError(f'geometry stream: expected a float tensor (B, S, 3, H, W), B >= 1 '
                             f'(one sequence: (1, S, 3, H, W)), in [0, 1], got {got}')
        height, width = images.shape[-2:]
        if height % patch or width % patch:
            raise InputError(f'geometry stream: image size {height}x{width} is not a multiple '
                             f'of the patch size {patch}; resize or crop the frames')
        count = images.shape[1]
        flags = [bool(keyframe)] * count if isinstance(keyframe, bool) else list(keyframe)
        if len(flags) != count:
            raise InputError(f'geometry stream: {len(flags)} keyframe flags for {count} frames')
        return flags
