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
* Integrity: MCAP chunks carry their CRC32 and the footer the summary CRC (rosbags writes 0,
  "not checked"); sqlite3 bags get a table ``mv3dpose_crc32`` with one key per message
  (CRC32 of the data, and of topic id and timestamp) and per topic record, which ros2 bag
  ignores. Readers verify both, so a
  corrupted payload is a ``BagError`` naming the file and the chunk (MCAP) or the message
  (sqlite3) instead of wrong values. Bags without CRCs (other writers) are read unchecked.
* Crash safety: ``BagWriter.checkpoint`` closes the pending MCAP chunk and flushes it (sqlite3:
  commits), so a writer killed with SIGKILL leaves a partial file in which everything up to the
  last checkpoint is intact; ``salvage`` turns such a ``.NAME.partial-PID`` directory into a
  complete bag (``mv3dpose bag recover``).
"""

from binascii import crc32
import functools
import os
from pathlib import Path
import re
import shutil
import sqlite3
import struct
from typing import Any, Dict, Iterable, Iterator, List, NamedTuple, Optional, Sequence, Tuple
from typing import Union

from mv3dpose_ros.core.files import load_yaml, LoadError, read_text
from mv3dpose_ros.core.files import temp_path_beside as _temp_path_beside
import numpy as np
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability
from rosbags.interfaces import QosTime
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.rosbag2.metadata import parse_qos
from rosbags.rosbag2.storage_mcap import DECOMPRESSORS, McapWriter
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Writer
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


MCAP_MAGIC = b'\x89MCAP0\r\n'
CRC_TABLE = 'mv3dpose_crc32'
_U64 = struct.Struct('<Q')


def _signed(key: int) -> int:
    return key - (1 << 64) if key >= 1 << 63 else key


def _message_key(topic_id: int, timestamp: int, data: bytes) -> int:
    """Return the signed 64-bit integrity key of one sqlite3 message row."""
    where = crc32(struct.pack('<qq', int(timestamp), int(topic_id)))
    return _signed((crc32(bytes(data)) << 32) | where)


def _topic_key(*row) -> int:
    """Return the integrity key of one ``topics`` row (id, name, type, format, QoS)."""
    text = '\x00'.join(str(v) for v in row).encode('utf-8', 'surrogateescape')
    return _signed((crc32(text) << 32) | crc32(b'mv3dpose topic row'))


_TOPIC_ROWS = 'SELECT id, name, type, serialization_format, offered_qos_profiles FROM topics'


def _check_metadata(path: Path) -> None:
    """Read ``metadata.yaml`` with the bounded loader before rosbags does (alias bombs)."""
    meta = path / 'metadata.yaml'
    try:
        data = load_yaml(read_text(meta, 16 * 1024 * 1024))
    except (OSError, LoadError) as exc:
        raise BagError(f'{meta}: unreadable bag metadata: {exc}') from None
    info = data.get('rosbag2_bagfile_information') if isinstance(data, dict) else None
    files = info.get('relative_file_paths') if isinstance(info, dict) else None
    if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
        raise BagError(f'{meta}: no rosbag2_bagfile_information.relative_file_paths list')
    for name in files:
        inside = (path / name).resolve()
        if path.resolve() not in inside.parents:
            raise BagError(f'{meta}: relative_file_paths entry {name!r} leaves the bag folder')


def _mcap_summary_crc(path: Path) -> None:
    """Verify the footer's summary CRC of an MCAP file (when it has one)."""
    size = path.stat().st_size
    if size < len(MCAP_MAGIC) * 2 + 29:
        raise BagError(f'{path}: truncated MCAP file ({size} bytes)')
    with open(path, 'rb') as f:
        f.seek(size - 8 - 29)
        footer = f.read(29)
        if footer[0] != 0x02 or f.read(8) != MCAP_MAGIC:
            raise BagError(f'{path}: no MCAP footer (truncated or still being written; '
                           'mv3dpose bag recover salvages interrupted recordings)')
        start, _, crc = struct.unpack('<QQI', footer[9:])
        if crc == 0:
            return
        start = start or size - 37      # no summary section: the CRC covers the footer only
        if not 8 <= start <= size - 37:
            raise BagError(f'{path}: MCAP footer points outside the file (summary at {start})')
        f.seek(start)
        summary = f.read(size - 12 - start)
    if crc32(summary) != crc:
        raise BagError(f'{path}: summary section (chunk index, statistics) fails its CRC: '
                       'the file is corrupt')


def _mcap_records(f, start: int, end: int) -> Iterator[Tuple[int, int, bytes]]:
    """Yield ``(opcode, offset, body)`` of the records in ``[start, end)``; stop when short."""
    pos = start
    while pos + 9 <= end:
        f.seek(pos)
        head = f.read(9)
        op, length = head[0], _U64.unpack_from(head, 1)[0]
        if length > end - pos - 9:
            return
        yield op, pos, f.read(length)
        pos += 9 + length


def _chunk_records(body: bytes, path: Path, index: int, offset: int) -> bytes:
    """Return the uncompressed records of an MCAP chunk record; BagError if corrupt."""
    where = f'{path}: chunk {index} (at byte {offset})'
    try:
        _, _, usize, crc = struct.unpack_from('<QQQI', body, 0)
        (n,) = struct.unpack_from('<I', body, 28)
        compression = body[32:32 + n].decode()
        (clen,) = _U64.unpack_from(body, 32 + n)
        packed = body[40 + n:40 + n + clen]
        if len(packed) != clen:
            raise BagError(f'{where}: truncated')
        raw = DECOMPRESSORS[compression](packed, usize)
    except BagError:
        raise
    except Exception as exc:  # noqa: B902 - struct, unicode, lz4 and zstd errors
        raise BagError(f'{where}: unreadable ({exc or type(exc).__name__})') from None
    if len(raw) != usize:
        raise BagError(f'{where}: {len(raw)} bytes, its header says {usize}')
    if crc and crc32(raw) != crc:
        raise BagError(f'{where}: CRC mismatch (stored {crc:08x}, computed '
                       f'{crc32(raw):08x}): the bag is corrupt')
    return raw


def verify_mcap_chunks(path: PathLike) -> int:
    """Check the CRC of every chunk of an MCAP file; return the count or raise BagError."""
    path = Path(path)
    count = 0
    with open(path, 'rb') as f:
        size = f.seek(0, 2)
        for op, offset, body in _mcap_records(f, len(MCAP_MAGIC), size):
            if op == 0x06:
                _chunk_records(body, path, count, offset)
                count += 1
            elif op == 0x0F:   # DataEnd
                break
    return count


def _verify_sqlite(db: Path) -> Optional[int]:
    """Check every message row of a sqlite3 bag against its key; None if it has no keys."""
    try:
        with sqlite3.connect(f'file:{db}?mode=ro', uri=True) as conn:
            if not conn.execute('SELECT 1 FROM sqlite_master WHERE name = ?',
                                (CRC_TABLE,)).fetchone():
                return None
            conn.create_function('mv3dpose_key', 3, _message_key, deterministic=True)
            (rows,) = conn.execute('SELECT COUNT(*) FROM messages').fetchone()
            (keys,) = conn.execute(f'SELECT COUNT(*) FROM {CRC_TABLE}').fetchone()
            topic_rows = list(conn.execute(_TOPIC_ROWS))
            known = {k for (k,) in conn.execute(f'SELECT key FROM {CRC_TABLE}')}
            bad = conn.execute(
                'SELECT m.id, t.name, m.timestamp FROM messages m LEFT JOIN topics t '
                'ON t.id = m.topic_id WHERE mv3dpose_key(m.topic_id, m.timestamp, m.data) '
                f'NOT IN (SELECT key FROM {CRC_TABLE}) LIMIT 1').fetchone()
        conn.close()
    except sqlite3.Error as exc:
        raise BagError(f'{db}: not a readable sqlite3 bag (corrupt): {exc}') from None
    if bad is not None:
        raise BagError(f'{db}: message row {bad[0]} (topic {bad[1]}, {bad[2]} ns) fails its '
                       'CRC (data, topic or timestamp changed): the bag is corrupt')
    for row in topic_rows:
        if _topic_key(*row) not in known:
            raise BagError(f'{db}: topic record {row[1]!r} fails its CRC (name, type or QoS '
                           'changed): the bag is corrupt')
    if rows + len(topic_rows) != keys:
        raise BagError(f'{db}: {rows} message and {len(topic_rows)} topic rows but {keys} CRC '
                       'keys: rows were added or removed, the bag is corrupt')
    return rows


def verify_bag(path: PathLike) -> str:
    """
    Check the CRCs of every storage file of a bag (reads it all once); return a summary.

    Raises ``BagError`` naming the file and the chunk (MCAP) or message row (sqlite3).
    """
    done = []
    for f in _storage_files(Path(path)):
        if f.suffix == '.mcap':
            _mcap_summary_crc(f)
            done.append(f'{f.name}: {verify_mcap_chunks(f)} chunk CRCs verified')
        elif f.suffix == '.db3':
            n = _verify_sqlite(f)
            done.append(f'{f.name}: ' + (f'{n} message CRCs verified' if n is not None
                                         else 'no CRCs (written by another tool), unchecked'))
    return '; '.join(done) or 'no storage file'


def _storage_files(path: Path) -> List[Path]:
    if path.is_dir():
        return sorted(list(path.glob('*.mcap')) + list(path.glob('*.db3')))
    return [path]


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
            _check_metadata(self.path)
        for f in _storage_files(self.path):
            if f.suffix == '.mcap' and f.exists():
                _mcap_summary_crc(f)
        try:
            self._reader = Reader(self.path)
            self._reader.open()
        except Exception as exc:  # noqa: B902 - rosbags raises many types for bad files
            raise _bag_error(self.path, exc) from exc
        self._keys = self._load_keys()

    def _load_keys(self) -> Optional[np.ndarray]:
        """Return the sorted integrity keys of a sqlite3 bag, or None if it has none."""
        dbs = [f for f in _storage_files(self.path) if f.suffix == '.db3']
        if not dbs:
            return None
        keys = []
        try:
            for db in dbs:
                with sqlite3.connect(f'file:{db}?mode=ro', uri=True) as conn:
                    if not conn.execute('SELECT 1 FROM sqlite_master WHERE name = ?',
                                        (CRC_TABLE,)).fetchone():
                        return None
                    keys += [k for (k,) in conn.execute(f'SELECT key FROM {CRC_TABLE}')]
                    topic_rows = list(conn.execute(_TOPIC_ROWS))
        except sqlite3.Error as exc:
            raise _bag_error(self.path, exc) from exc
        if not all(isinstance(k, int) for k in keys):
            raise BagError(f'{self.path}: table {CRC_TABLE} holds non-integer keys (corrupt)')
        keys = np.sort(np.array(keys, dtype=np.int64))
        for row in topic_rows:
            key = _topic_key(*row)
            i = int(np.searchsorted(keys, key))
            if i >= len(keys) or keys[i] != key:
                raise BagError(f'{self.path}: topic record {row[1]!r} fails its CRC (name, type '
                               'or QoS changed): the bag is corrupt')
        return keys

    def _check_key(self, conn, stamp: int, data: bytes) -> None:
        key = _message_key(conn.id, stamp, data)
        i = int(np.searchsorted(self._keys, key))
        if i >= len(self._keys) or self._keys[i] != key:
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
                for f in _storage_files(self.path):   # name the chunk
                    if f.suffix == '.mcap':
                        verify_mcap_chunks(f)
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

class _CrcMcapWriter(McapWriter):
    """rosbags' MCAP writer, plus chunk and summary CRCs and checkpoints."""

    def close_chunk(self) -> None:
        """Write the pending chunk and patch its uncompressed CRC into the record."""
        crc = crc32(self.chunk.bio.getbuffer())
        start = self.bio.tell()
        super().close_chunk()
        end = self.bio.tell()
        self.bio.seek(start + 1 + 8 + 24)   # opcode, length, start/end time, size
        self.bio.write(struct.pack('<I', crc))
        self.bio.seek(end)

    def checkpoint(self) -> None:
        """Close the pending chunk and hand everything to the OS (survives SIGKILL)."""
        if self.chunk.bio.tell():
            self.close_chunk()
        self.bio.flush()

    def close(self, version: int, metadata: str) -> None:
        """Finish the file, then fill in the footer's summary CRC."""
        super().close(version, metadata)
        with open(self.path, 'r+b') as f:
            size = f.seek(0, 2)
            f.seek(size - 8 - 29 + 9)
            start = _U64.unpack(f.read(8))[0]
            f.seek(start)
            crc = crc32(f.read(size - 12 - start))
            f.seek(size - 12)
            f.write(struct.pack('<I', crc))


class _CheckpointSqlite3Writer(Sqlite3Writer):
    """rosbags' sqlite3 writer with checkpoints (commits)."""

    def checkpoint(self) -> None:
        """Commit what was written so far."""
        self.conn.commit()


class _Writer(Writer):
    STORAGE_PLUGINS = {StoragePlugin.MCAP: _CrcMcapWriter,
                       StoragePlugin.SQLITE3: _CheckpointSqlite3Writer}


def _add_crc_table(db: Path) -> None:
    """Add the integrity key of every message of a finished sqlite3 bag."""
    with sqlite3.connect(db) as conn:
        conn.create_function('mv3dpose_key', 3, _message_key, deterministic=True)
        conn.execute(f'CREATE TABLE {CRC_TABLE} (key INTEGER NOT NULL)')
        conn.execute(f'INSERT INTO {CRC_TABLE} SELECT mv3dpose_key(topic_id, timestamp, data) '
                     'FROM messages')
        conn.executemany(f'INSERT INTO {CRC_TABLE} VALUES (?)',
                         [(_topic_key(*row),) for row in conn.execute(_TOPIC_ROWS)])
    conn.close()


def is_bag(path: PathLike) -> bool:
    """
    Tell whether ``path`` is a rosbag2 bag this tool may replace.

    A storage file (``.mcap``, ``.db3``), or a directory holding ``metadata.yaml`` and
    otherwise only bag files (storage files, their journals, ``.yaml``), nothing nested.
    """
    p = Path(path)
    if p.is_file():
        return p.suffix in ('.mcap', '.db3')
    if not p.is_dir() or not (p / 'metadata.yaml').is_file():
        return False
    allowed = re.compile(r'.*\.(mcap|db3|db3-journal|db3-wal|db3-shm|yaml|zstd|lz4)$')
    return all(c.is_file() and allowed.match(c.name) for c in p.iterdir())


def _check_replaceable(path: Path) -> None:
    if path.exists() and not is_bag(path):
        kind = 'directory' if path.is_dir() else 'file'
        raise BagError(f'{path}: exists and is a {kind} that is not a rosbag2 bag; '
                       '--overwrite replaces only bags, so nothing was written')


def partial_dirs(path: PathLike) -> List[Path]:
    """Return the ``.NAME.partial-PID`` directories of ``path`` left by dead writers."""
    target = Path(path)
    found = []
    for d in sorted(target.parent.glob(f'.{target.name}.partial-*')):
        pid = d.name.rsplit('-', 1)[-1]
        if not pid.isdigit() or not d.is_dir():
            continue
        try:
            os.kill(int(pid), 0)
            alive = int(pid) != os.getpid()
        except ProcessLookupError:
            alive = False
        except PermissionError:
            alive = True
        if not alive:
            found.append(d)
    return found


class BagWriter:
    """
    Write a rosbag2 bag atomically: into a hidden temp dir, renamed into place on success.

    Use as a context manager; an exception inside the ``with`` block discards the partial bag.
    With ``overwrite`` an existing *bag* at ``path`` is replaced; anything else there is an
    error (before anything is written).
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
        _check_replaceable(self.path)
        parent = self.path.parent
        if not parent.is_dir():
            raise BagError(f'{self.path}: output folder {parent} does not exist')
        self._tmp_root = parent / f'.{self.path.name}.partial-{os.getpid()}'
        shutil.rmtree(self._tmp_root, ignore_errors=True)
        self._tmp_root.mkdir()
        self._writer = _Writer(self._tmp_root / self.path.name, version=9,
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

    def checkpoint(self) -> None:
        """Make everything written so far survive a SIGKILL (see ``salvage``)."""
        if not self._closed and self._writer.storage is not None:
            self._writer.storage.checkpoint()

    def close(self) -> Path:
        """Finish the bag and move it into place; return its path."""
        if self._closed:
            return self.path
        try:
            self._writer.close()
            for db in (self._tmp_root / self.path.name).glob('*.db3'):
                _add_crc_table(db)
            if self.path.exists():
                if not self.overwrite:
                    raise BagError(f'{self.path}: appeared while writing; not overwriting it')
                _check_replaceable(self.path)
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
    """``core.files.temp_path_beside`` with a missing output folder as ``BagError``."""
    try:
        return _temp_path_beside(output)
    except FileNotFoundError as exc:
        raise BagError(str(exc)) from None


# ------------------------------------------------------------------------------------ salvage

class SalvageReport(NamedTuple):
    """What ``salvage`` recovered."""

    output: Path
    messages: int
    topics: Dict[str, int]
    lost_tail_bytes: int     # bytes after the last intact chunk (MCAP), 0 for sqlite3
    note: str


def _read_str(buf: bytes, pos: int) -> Tuple[str, int]:
    (n,) = struct.unpack_from('<I', buf, pos)
    return buf[pos + 4:pos + 4 + n].decode(), pos + 4 + n


def _mcap_items(path: Path) -> Tuple[list, int, int]:
    """Return ``(items, intact_end, size)`` of a partial MCAP: schema/channel/message tuples."""
    items = []
    with open(path, 'rb') as f:
        if f.read(8) != MCAP_MAGIC:
            raise BagError(f'{path}: not an MCAP file (bad magic)')
        size = f.seek(0, 2)
        end = len(MCAP_MAGIC)
        index = 0

        def parse(op: int, body: bytes) -> None:
            if op == 0x03:
                (sid,) = struct.unpack_from('<H', body, 0)
                name, _ = _read_str(body, 2)
                items.append(('schema', sid, name))
            elif op == 0x04:
                cid, sid = struct.unpack_from('<HH', body, 0)
                topic, pos = _read_str(body, 4)
                _, pos = _read_str(body, pos)            # message encoding
                (mlen,) = struct.unpack_from('<I', body, pos)
                meta, qos, mpos = body[pos + 4:pos + 4 + mlen], [], 0
                while mpos < len(meta):
                    key, mpos = _read_str(meta, mpos)
                    value, mpos = _read_str(meta, mpos)
                    if key == 'offered_qos_profiles':
                        qos = parse_qos(value)
                items.append(('channel', cid, (sid, topic, qos)))
            elif op == 0x05:
                cid, _, stamp = struct.unpack_from('<HIQ', body, 0)
                items.append(('message', cid, (stamp, body[22:])))

        for op, offset, body in _mcap_records(f, len(MCAP_MAGIC), size):
            try:
                if op == 0x06:
                    raw = _chunk_records(body, path, index, offset)
                    index += 1
                    pos = 0
                    while pos + 9 <= len(raw):
                        iop, ilen = raw[pos], _U64.unpack_from(raw, pos + 1)[0]
                        parse(iop, raw[pos + 9:pos + 9 + ilen])
                        pos += 9 + ilen
                elif op in (0x03, 0x04, 0x05):
                    parse(op, body)
                elif op == 0x0F:
                    end = offset + 9 + len(body)
                    break
            except (BagError, struct.error, UnicodeDecodeError):
                break            # corrupt from here on: keep what came before
            end = offset + 9 + len(body)
    return items, end, size


def salvage(source: PathLike, output: PathLike, overwrite: bool = False) -> SalvageReport:
    """
    Write the intact messages of an interrupted recording into a new, complete bag.

    ``source`` is a ``.NAME.partial-PID`` directory (or the storage file inside it) left by
    a writer that was killed. MCAP: every chunk whose CRC checks is kept; the incomplete tail
    (at most what came after the writer's last checkpoint) is lost. sqlite3: every committed
    row is kept. The bag is written atomically at ``output`` (same storage as the source).
    """
    src = Path(source)
    files = [f for f in (src.rglob('*') if src.is_dir() else [src])
             if f.suffix in ('.mcap', '.db3')]
    if len(files) != 1:
        raise BagError(f'{src}: expected one .mcap or .db3 file to salvage, found '
                       f'{len(files)}')
    store = files[0]
    topics: Dict[int, Tuple[str, str, list]] = {}
    messages: List[Tuple[int, int, bytes]] = []
    lost = 0
    if store.suffix == '.mcap':
        items, end, size = _mcap_items(store)
        schemas = {}
        for kind, key, value in items:
            if kind == 'schema':
                schemas[key] = value
            elif kind == 'channel':
                sid, topic, qos = value
                topics[key] = (topic, schemas.get(sid, ''), qos)
            elif key in topics:
                messages.append((key, value[0], value[1]))
        lost = size - end
        storage = 'mcap'
    else:
        try:
            with sqlite3.connect(store) as conn:
                for tid, name, msgtype, qos in conn.execute(
                        'SELECT id, name, type, offered_qos_profiles FROM topics'):
                    topics[tid] = (name, msgtype, parse_qos(qos) if qos else [])
                messages = [(t, int(s), bytes(d)) for t, s, d in conn.execute(
                    'SELECT topic_id, timestamp, data FROM messages ORDER BY id')
                    if t in topics]
            conn.close()
        except (sqlite3.Error, ValueError, TypeError) as exc:
            raise BagError(f'{store}: cannot read the partial sqlite3 bag: {exc}') from None
        storage = 'sqlite3'
    if not topics:
        raise BagError(f'{store}: nothing to salvage (no intact topic record; '
                       f'{lost} bytes unreadable)')
    counts: Dict[str, int] = {}
    with BagWriter(output, storage=storage, overwrite=overwrite) as writer:
        for tid, (topic, msgtype, qos) in topics.items():
            try:
                writer.add_topic(topic, msgtype, qos)
            except (BagError, ValueError) as exc:
                raise BagError(f'{store}: topic {topic}: {exc}') from None
            counts[topic] = 0
        for tid, stamp, data in sorted(messages, key=lambda m: m[1]):
            writer.write(topics[tid][0], stamp, data)
            counts[topics[tid][0]] += 1
    note = (f'{lost} bytes of an incomplete chunk after the last checkpoint were dropped' if lost
            else 'the file ended at a checkpoint; messages not yet checkpointed were lost')
    return SalvageReport(Path(output), len(messages), counts, lost, note)
