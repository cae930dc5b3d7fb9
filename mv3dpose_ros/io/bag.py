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
Read and write rosbag2 files (MCAP or sqlite3) without rosbag2, on the ``rosbags`` library.

Why this module exists: ``ros2 bag`` is not part of the ROS 2 wheels, yet users replay and record
rigs. Everything here is rclpy-free so offline tools and tests can use it; the bags it writes are
standard rosbag2 v9 directories that ``ros2 bag play``, RViz and Foxglove open on a full install.

* One typestore: ``Stores.ROS2_JAZZY`` (pinned; ``Stores.LATEST`` is Kilted) plus every ``.msg``
  of ``mv3dpose_msgs``, read from the installed share directory or the source tree, so the
  ``.msg`` files stay the single source of truth.
* ``BagWriter`` writes into a hidden temporary directory beside the target and renames it into
  place only when closed without error: an interrupted or failed write never leaves a bag that
  looks complete.
* ``BagReader`` turns the library's assorted exceptions for missing, corrupt or truncated files
  into one ``BagError`` that names the file.
"""

import functools
import os
from pathlib import Path
import shutil
import tempfile
from typing import Any, Dict, Iterable, Iterator, List, NamedTuple, Optional, Sequence, Union

from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability
from rosbags.interfaces import QosTime
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import get_types_from_msg, Stores
from rosbags.typesys import get_typestore as _rosbags_typestore

MSG_PACKAGE = 'mv3dpose_msgs'
STORAGES = ('mcap', 'sqlite3')
DEFAULT_STORAGE = 'mcap'
_PLUGINS = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}

PathLike = Union[str, os.PathLike]


class BagError(RuntimeError):
    """A bag cannot be read or written; the message names the file and the reason."""


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


# ------------------------------------------------------------------------------------ typestore

def msg_dir() -> Path:
    """
    Return the folder holding the ``mv3dpose_msgs`` ``.msg`` files.

    The installed share directory (ament index) wins; the source tree beside this package is the
    fallback so that a plain checkout works before ``colcon build``.
    """
    try:
        from ament_index_python.packages import get_package_share_directory
        share = Path(get_package_share_directory(MSG_PACKAGE)) / 'msg'
        if any(share.glob('*.msg')):
            return share
    except Exception:  # noqa: B902 - ament index absent or package not installed
        pass
    source = Path(__file__).resolve().parents[2] / MSG_PACKAGE / 'msg'
    if any(source.glob('*.msg')):
        return source
    raise BagError(f'cannot find the {MSG_PACKAGE} .msg files: not installed (ament index) '
                   f'and not in the source tree at {source}')


@functools.lru_cache(maxsize=1)
def get_typestore():
    """Return the ROS 2 Jazzy typestore with every ``mv3dpose_msgs`` message registered."""
    store = _rosbags_typestore(Stores.ROS2_JAZZY)
    types: Dict[str, Any] = {}
    for path in sorted(msg_dir().glob('*.msg')):
        types.update(get_types_from_msg(path.read_text(), f'{MSG_PACKAGE}/msg/{path.stem}'))
    store.register(types)
    return store


def normalise_type(msgtype: str) -> str:
    """Turn ``pkg/Type`` or ``pkg/msg/Type`` into the ``pkg/msg/Type`` form bags use."""
    parts = msgtype.split('/')
    if len(parts) == 2:
        return f'{parts[0]}/msg/{parts[1]}'
    if len(parts) == 3:
        return msgtype
    raise ValueError(f'message type {msgtype!r} is not of the form pkg/msg/Type')


def serialize(msg: Any, msgtype: str) -> bytes:
    """Serialise a rosbags message object to CDR bytes."""
    return bytes(get_typestore().serialize_cdr(msg, normalise_type(msgtype)))


def deserialize(data: bytes, msgtype: str) -> Any:
    """Deserialise CDR bytes into a rosbags message object (a dataclass)."""
    return get_typestore().deserialize_cdr(data, normalise_type(msgtype))


# ------------------------------------------------------------------------------------ QoS

def make_qos(reliable: bool = True, depth: int = 10, transient_local: bool = False) -> Qos:
    """Build a rosbags QoS profile for ``offered_qos_profiles`` (no rclpy needed)."""
    default = QosTime(0, 0)  # rmw: 0 = the default, i.e. no deadline / lifespan / lease
    return Qos(
        history=QosHistory.KEEP_LAST, depth=int(depth),
        reliability=QosReliability.RELIABLE if reliable else QosReliability.BEST_EFFORT,
        durability=QosDurability.TRANSIENT_LOCAL if transient_local else QosDurability.VOLATILE,
        deadline=default, lifespan=default, liveliness=QosLiveliness.AUTOMATIC,
        liveliness_lease_duration=default, avoid_ros_namespace_conventions=False)


# ------------------------------------------------------------------------------------ reading

def _bag_error(path: Path, exc: BaseException) -> BagError:
    reason = str(exc) or type(exc).__name__
    return BagError(f'{path}: not a readable rosbag2 bag (corrupt, truncated or incomplete): '
                    f'{reason}')


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
        try:
            self._reader = Reader(self.path)
            self._reader.open()
        except Exception as exc:  # noqa: B902 - rosbags raises many types for bad files
            raise _bag_error(self.path, exc) from exc

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
                yield BagMessage(conn.topic, conn.msgtype, int(stamp), bytes(data))
        except Exception as exc:  # noqa: B902
            raise _bag_error(self.path, exc) from exc
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


# ------------------------------------------------------------------------------------ writing

class BagWriter:
    """
    Write a rosbag2 bag atomically: into a hidden temp dir, renamed into place on success.

    Use as a context manager; an exception inside the ``with`` block discards the partial bag.
    """

    def __init__(self, path: PathLike, storage: str = DEFAULT_STORAGE, overwrite: bool = False):
        """Prepare to write a bag directory at ``path`` with ``storage`` 'mcap' or 'sqlite3'."""
        if storage not in STORAGES:
            raise BagError(f'{path}: unknown storage {storage!r}; choose one of {STORAGES}')
        self.path = Path(path)
        self.storage = storage
        self.overwrite = overwrite
        if self.path.exists() and not overwrite:
            raise BagError(f'{self.path}: exists already; choose another output or remove it')
        parent = self.path.parent
        if not parent.is_dir():
            raise BagError(f'{self.path}: output folder {parent} does not exist')
        self._tmp_root = parent / f'.{self.path.name}.partial-{os.getpid()}'
        shutil.rmtree(self._tmp_root, ignore_errors=True)
        self._tmp_root.mkdir()
        self._writer = Writer(self._tmp_root / self.path.name, version=9,
                              storage_plugin=_PLUGINS[storage])
        self._writer.open()
        self._conns: Dict[str, Any] = {}
        self.counts: Dict[str, int] = {}
        self._closed = False

    def __enter__(self) -> 'BagWriter':
        """Return self."""
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        """Finish the bag, or discard it if the block raised."""
        if exc_type is None:
            self.close()
        else:
            self.abort()

    @property
    def topics(self) -> List[str]:
        """Topics added so far."""
        return list(self._conns)

    def add_topic(self, topic: str, msgtype: str, qos: Optional[Sequence[Qos]] = None) -> None:
        """Add a topic of ``msgtype`` with its offered QoS profiles (defaults: none recorded)."""
        if topic in self._conns:
            return
        msgtype = normalise_type(msgtype)
        store = get_typestore()
        if msgtype not in store.fielddefs:
            raise BagError(f'{self.path}: unknown message type {msgtype} for topic {topic} '
                           '(not in the Jazzy typestore nor in mv3dpose_msgs)')
        self._conns[topic] = self._writer.add_connection(
            topic, msgtype, typestore=store, offered_qos_profiles=list(qos or []))
        self.counts[topic] = 0

    def write(self, topic: str, timestamp_ns: int, data: bytes) -> None:
        """Write CDR bytes on ``topic`` (added before) at ``timestamp_ns``."""
        conn = self._conns.get(topic)
        if conn is None:
            raise BagError(f'{self.path}: topic {topic} was not added before writing')
        self._writer.write(conn, int(timestamp_ns), data)
        self.counts[topic] += 1

    def write_msg(self, topic: str, timestamp_ns: int, msg: Any, msgtype: str,
                  qos: Optional[Sequence[Qos]] = None) -> None:
        """Serialise a rosbags message object and write it, adding the topic if needed."""
        self.add_topic(topic, msgtype, qos)
        self.write(topic, timestamp_ns, serialize(msg, msgtype))

    def close(self) -> Path:
        """Finish the bag and move it into place; return its path."""
        if self._closed:
            return self.path
        try:
            self._writer.close()
            if self.path.exists():
                if not self.overwrite:
                    raise BagError(f'{self.path}: appeared while writing; not overwriting it')
                if self.path.is_dir():
                    shutil.rmtree(self.path)
                else:
                    self.path.unlink()
            os.replace(self._tmp_root / self.path.name, self.path)
        except BaseException:
            self.abort()
            raise
        finally:
            shutil.rmtree(self._tmp_root, ignore_errors=True)
            self._closed = True
        return self.path

    def abort(self) -> None:
        """Discard everything written so far; the target path is left untouched."""
        if self._closed:
            return
        self._closed = True
        try:
            if self._writer.storage is not None:
                self._writer.storage.close(self._writer.version, '')
        except Exception:  # noqa: B902 - closing a half-written file may fail; it is deleted
            pass
        shutil.rmtree(self._tmp_root, ignore_errors=True)


def bag_path_type(path: PathLike) -> str:
    """Return 'bag' for a rosbag2 directory or storage file, 'file' otherwise (for dispatch)."""
    p = Path(path)
    if p.is_dir() and (p / 'metadata.yaml').exists():
        return 'bag'
    if p.suffix in ('.mcap', '.db3'):
        return 'bag'
    return 'file'


def temp_path_beside(output: PathLike) -> str:
    """
    Create an empty hidden temp file beside ``output`` (same folder, same suffix).

    Writers fill it and ``os.replace`` it onto ``output`` when done, so a crash never leaves a
    half-written file under the final name. Permissions follow the umask like ``open``.
    """
    out = Path(output)
    if not out.parent.is_dir():
        raise BagError(f'{output}: output folder {out.parent} does not exist')
    fd, tmp = tempfile.mkstemp(prefix=f'.{out.stem}.', suffix=f'.partial{out.suffix}',
                               dir=out.parent)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)
    return tmp
