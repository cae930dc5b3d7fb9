# Copyright 2026 The mv3dpose_ros Authors
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
``BagReader``: a rosbag2 bag read through ``rosbags``, every failure a ``BagError``.

The library's assorted exceptions for missing, corrupt or truncated files become one
``BagError`` that names the file, also when they only show while iterating (a truncated
MCAP); CRCs are checked as the messages are read (``crc``).
"""

from pathlib import Path
from typing import Dict, Iterable, Iterator, List, NamedTuple, Optional

from mv3dpose_ros.io.bag.crc import (has_key, mcap_summary_crc, message_key, sqlite_keys,
                                     unreadable, verify_mcap_chunks)
from mv3dpose_ros.io.bag.files import BagError, check_metadata, PathLike, storage_files
from mv3dpose_ros.io.bag.typestore import get_typestore
from rosbags.interfaces import Qos
from rosbags.rosbag2 import Reader


class BagMessage(NamedTuple):
    """One serialised message of a bag."""

    topic: str
    msgtype: str          # e.g. 'sensor_msgs/msg/Image'
    timestamp: int        # [ns] bag (receive) time
    data: bytes           # CDR bytes as published


class TopicSummary(NamedTuple):
    """What ``BagReader.topics`` reports per topic."""

    msgtype: str
    count: int
    qos: List[Qos]        # offered QoS profiles recorded with the topic (may be empty)


class BagReader:
    """
    Read a rosbag2 directory (or a lone ``.mcap`` / ``.db3`` file).

    Use as a context manager. Every failure of the underlying library becomes a ``BagError``
    naming the file, also when it only shows while iterating (a truncated MCAP).
    """

    def __init__(self, path: PathLike):
        """Open ``path``; raise ``BagError`` if it is missing or not a bag."""
        self.path = Path(path)
        if not self.path.exists():
            raise BagError(f'{self.path}: no such bag (file or directory does not exist)')
        if self.path.is_dir() and not (self.path / 'metadata.yaml').exists():
            raise BagError(f'{self.path}: not a rosbag2 bag (no metadata.yaml in the directory)')
        if self.path.is_dir():
            check_metadata(self.path)
        for f in storage_files(self.path):
            if f.suffix == '.mcap' and f.exists():
                mcap_summary_crc(f)
        try:
            self._reader = Reader(self.path)
            self._reader.open()
        except Exception as exc:  # noqa: B902 - rosbags raises many types for bad files
            raise unreadable(self.path, exc) from exc
        self._keys = sqlite_keys(self.path)

    def _check_key(self, conn, stamp: int, data: bytes) -> None:
        if not has_key(self._keys, message_key(conn.id, stamp, data)):
            raise BagError(f'{self.path}: message on {conn.topic} at {stamp} ns fails its '
                           'CRC (data, topic or timestamp changed): the bag is corrupt')

    def __enter__(self) -> 'BagReader':
        """Return self."""
        return self

    def __exit__(self, *exc) -> None:
        """Close the bag."""
        self.close()

    def close(self) -> None:
        """Close the underlying reader."""
        if getattr(self, '_reader', None) is not None and self._reader.is_open:
            self._reader.close()

    @property
    def storage(self) -> str:
        """Storage identifier: 'mcap' or 'sqlite3'."""
        files = list(self.path.rglob('*.mcap')) if self.path.is_dir() else [self.path]
        return 'mcap' if any(f.suffix == '.mcap' for f in files) else 'sqlite3'

    @property
    def start_ns(self) -> int:
        """Timestamp [ns] of the first message (0 for an empty bag)."""
        return int(self._reader.start_time) if self.message_count else 0

    @property
    def end_ns(self) -> int:
        """Timestamp [ns] of the last message (0 for an empty bag)."""
        # rosbags reports the time just *after* the latest message
        return int(self._reader.end_time) - 1 if self.message_count else 0

    @property
    def duration_s(self) -> float:
        """Time between the first and the last message [s]."""
        return (self.end_ns - self.start_ns) * 1e-9

    @property
    def message_count(self) -> int:
        """Return the number of messages over all topics."""
        return int(self._reader.message_count)

    def topics(self) -> Dict[str, TopicSummary]:
        """Return topic -> (type, message count, recorded QoS profiles), sorted by topic."""
        out: Dict[str, TopicSummary] = {}
        for conn in sorted(self._reader.connections, key=lambda c: c.topic):
            prev = out.get(conn.topic)
            qos = list(getattr(conn.ext, 'offered_qos_profiles', []) or [])
            count = conn.msgcount + (prev.count if prev else 0)
            out[conn.topic] = TopicSummary(conn.msgtype, count, (prev.qos if prev else []) + qos)
        return out

    def messages(self, topics: Optional[Iterable[str]] = None,
                 start_ns: Optional[int] = None) -> Iterator[BagMessage]:
        """Yield messages in timestamp order, optionally only ``topics`` and from ``start_ns``."""
        wanted = None if topics is None else set(topics)
        conns = [c for c in self._reader.connections if wanted is None or c.topic in wanted]
        if not conns:
            return
        seen = 0
        try:
            for conn, stamp, data in self._reader.messages(connections=conns, start=start_ns):
                seen += 1
                stamp, data = int(stamp), bytes(data)
                if self._keys is not None:
                    self._check_key(conn, stamp, data)
                yield BagMessage(conn.topic, conn.msgtype, stamp, data)
        except BagError:
            raise
        except Exception as exc:  # noqa: B902
            if 'checksum' in str(exc).lower() or 'chunk' in str(exc).lower():
                for f in storage_files(self.path):   # name the chunk
                    if f.suffix == '.mcap':
                        verify_mcap_chunks(f)
            raise unreadable(self.path, exc) from exc
        expected = sum(c.msgcount for c in conns)
        if start_ns is None and seen != expected:
            raise BagError(f'{self.path}: corrupt or truncated bag: read {seen} messages of the '
                           f'{expected} its index lists')

    def decoded(self, topics: Optional[Iterable[str]] = None) -> Iterator[tuple]:
        """Yield ``(topic, timestamp_ns, message)`` with rosbags message objects."""
        store = get_typestore()
        for m in self.messages(topics):
            try:
                msg = store.deserialize_cdr(m.data, m.msgtype)
            except Exception as exc:  # noqa: B902
                raise BagError(f'{self.path}: cannot decode a {m.msgtype} message on {m.topic} '
                               f'at {m.timestamp} ns: {exc}') from exc
            yield m.topic, m.timestamp, msg


def check_bag(path: PathLike) -> int:
    """Read and decode every message of a bag once; return the count or raise ``BagError``."""
    with BagReader(path) as reader:
        return sum(1 for _ in reader.decoded())
