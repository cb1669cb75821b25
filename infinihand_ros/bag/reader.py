"""Read rosbag2 bags (MCAP or sqlite3) with rosbags, turning every failure into a clear BagError.

``BagReader`` opens a bag with our message types registered, lists its topics and yields
deserialised messages of chosen topics in time order.
"""

from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from infinihand_ros.bag.typestore import build_typestore
from infinihand_ros.core.errors import BagError
from rosbags.highlevel import AnyReader
from rosbags.highlevel import AnyReaderError
from rosbags.rosbag2 import ReaderError


@dataclass(frozen=True)
class TopicInfo:
    """One topic of a bag: message type and count."""

    msgtype: str
    count: int


class BagReader:
    """Context manager over one rosbag2 bag directory."""

    def __init__(self, path: str | Path) -> None:
        """Remember the bag path; the bag is opened by ``with``."""
        self.path = Path(path)
        self._reader: AnyReader | None = None

    def __enter__(self) -> 'BagReader':
        """Open the bag.

        Raises:
            BagError: when the path is missing or the bag cannot be read.

        """
        if not self.path.exists():
            raise BagError(f'bag {self.path} does not exist; pass a rosbag2 directory')
        try:
            self._reader = AnyReader([self.path], default_typestore=build_typestore())
            self._reader.open()
        except (AnyReaderError, ReaderError, OSError, ValueError, KeyError) as exc:
            self._reader = None
            raise BagError(
                f'bag {self.path} cannot be read ({exc}); check that it is a complete rosbag2 '
                'directory (metadata.yaml plus .mcap or .db3)') from exc
        return self

    def __exit__(self, exc_type: object, exc: object, traceback: object) -> None:
        """Close the bag."""
        if self._reader is not None:
            self._reader.close()
            self._reader = None

    @property
    def _open_reader(self) -> AnyReader:
        if self._reader is None:
            raise RuntimeError('BagReader used outside its with-block')
        return self._reader

    def topics(self) -> dict[str, TopicInfo]:
        """Return every topic with its message type and message count."""
        infos: dict[str, TopicInfo] = {}
        for connection in self._open_reader.connections:
            known = infos.get(connection.topic)
            infos[connection.topic] = TopicInfo(
                connection.msgtype, connection.msgcount + (known.count if known else 0))
        return infos

    def duration_s(self) -> float:
        """Return the time between the first and the last message (s)."""
        reader = self._open_reader
        return max(reader.end_time - reader.start_time, 0) / 1e9

    def messages(self, topic_names: list[str]) -> Iterator[tuple[str, int, Any]]:
        """Yield (topic, bag timestamp in ns, message) of ``topic_names`` in time order.

        Raises:
            BagError: for a missing topic (naming the topics the bag has) or a message that
                cannot be deserialised.

        """
        reader = self._open_reader
        missing = sorted(set(topic_names) - {c.topic for c in reader.connections})
        if missing:
            raise BagError(f'bag {self.path} has no topic(s) {missing}; it has '
                           f'{sorted(self.topics())}')
        connections = [c for c in reader.connections if c.topic in topic_names]
        try:
            for connection, stamp, raw in reader.messages(connections=connections):
                yield connection.topic, stamp, reader.deserialize(raw, connection.msgtype)
        except (ReaderError, AnyReaderError, ValueError, KeyError, AssertionError) as exc:
            raise BagError(f'bag {self.path}: a message cannot be read ({exc}); the bag may be '
                           'truncated or corrupt') from exc
