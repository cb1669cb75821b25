"""Pairing images with CameraInfo by stamp, and the fallback intrinsics (image_transport style).

``CameraInfoPairing.add`` validates each CameraInfo (``bag.camera_msgs``: K all zeros, NaN,
zero focal lengths and zero sizes are refused) and keeps the newest ``capacity`` of them.
``intrinsics_for(stamp, width, height)`` returns the stored intrinsics whose stamp is nearest
the image's (within ``tolerance_ns``) and whose size matches, else the fallback intrinsics when
they are configured, else None (the model predicts the field of view). When the stream restarts
at an earlier stamp, ``forget_after`` drops the CameraInfos of the stream before, which lie
ahead of it.
"""

from collections import deque
from dataclasses import dataclass
from typing import Final

from infinihand_ros.bag.camera_msgs import camera_info_to_intrinsics
from infinihand_ros.bag.messages import ns_from_stamp
from infinihand_ros.core.datatypes import Intrinsics
from infinihand_ros.core.errors import InputError
from infinihand_ros.ros.estimator.config import FallbackIntrinsics
from sensor_msgs.msg import CameraInfo

#: Where a frame's intrinsics came from.
FROM_CAMERA_INFO: Final = 'camera_info'
FROM_FALLBACK: Final = 'fallback'
FROM_MODEL: Final = 'model'


@dataclass(frozen=True)
class IntrinsicsChoice:
    """The intrinsics given to the engine for one image and their source.

    Attributes:
        intrinsics: the intrinsics, or None to let the model predict the field of view.
        source: ``FROM_CAMERA_INFO``, ``FROM_FALLBACK`` or ``FROM_MODEL``.

    """

    intrinsics: Intrinsics | None
    source: str


def fallback_intrinsics(fallback: FallbackIntrinsics, width: int, height: int
                        ) -> Intrinsics | None:
    """Return the configured fallback for a ``width`` x ``height`` image, or None when off."""
    if not fallback.enabled:
        return None
    cx = fallback.cx if fallback.cx > 0 else width / 2.0
    cy = fallback.cy if fallback.cy > 0 else height / 2.0
    return Intrinsics(fallback.fx, fallback.fy, cx, cy, width, height)


class CameraInfoPairing:
    """Recent valid CameraInfos, looked up by image stamp (not thread-safe)."""

    def __init__(self, tolerance_ns: int, fallback: FallbackIntrinsics,
                 capacity: int = 64) -> None:
        """Start with no CameraInfo.

        Args:
            tolerance_ns: largest stamp difference of a pair, nanoseconds.
            fallback: intrinsics for images no CameraInfo pairs with.
            capacity: CameraInfos remembered (the newest).

        """
        self.tolerance_ns = tolerance_ns
        self.fallback = fallback
        self._infos: deque[tuple[int, Intrinsics]] = deque(maxlen=capacity)

    @property
    def has_infos(self) -> bool:
        """Return whether any valid CameraInfo was stored (the camera publishes them)."""
        return bool(self._infos)

    def paired(self, stamp_ns: int, width: int, height: int) -> Intrinsics | None:
        """Return the stored intrinsics nearest ``stamp_ns`` for this size, or None."""
        best: tuple[int, Intrinsics] | None = None
        for info_stamp, intrinsics in self._infos:
            gap = abs(info_stamp - stamp_ns)
            same_size = (intrinsics.width, intrinsics.height) == (width, height)
            if gap <= self.tolerance_ns and same_size and (best is None or gap < best[0]):
                best = (gap, intrinsics)
        return None if best is None else best[1]

    def add(self, msg: CameraInfo) -> None:
        """Store a CameraInfo message.

        Raises:
            InputError: for an unusable CameraInfo (named in the message); nothing is stored.

        """
        try:
            intrinsics = camera_info_to_intrinsics(msg)
        except InputError as exc:
            raise InputError(f'camera_info stamped {ns_from_stamp(msg.header.stamp)}: {exc}'
                             ) from exc
        self._infos.append((ns_from_stamp(msg.header.stamp), intrinsics))

    def forget_after(self, stamp_ns: int) -> None:
        """Forget the CameraInfos stamped more than the tolerance after ``stamp_ns``."""
        kept = [(stamp, info) for stamp, info in self._infos
                if stamp <= stamp_ns + self.tolerance_ns]
        self._infos.clear()
        self._infos.extend(kept)

    def intrinsics_for(self, stamp_ns: int, width: int, height: int) -> IntrinsicsChoice:
        """Return the intrinsics for an image of this stamp and size (see the module doc)."""
        paired = self.paired(stamp_ns, width, height)
        if paired is not None:
            return IntrinsicsChoice(paired, FROM_CAMERA_INFO)
        fallback = fallback_intrinsics(self.fallback, width, height)
        if fallback is not None:
            return IntrinsicsChoice(fallback, FROM_FALLBACK)
        return IntrinsicsChoice(None, FROM_MODEL)
