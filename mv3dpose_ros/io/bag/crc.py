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
Integrity of the bags this package writes, checked by its readers.

MCAP chunks carry their CRC32 and the footer the summary CRC (rosbags writes 0, "not
checked"); sqlite3 bags get a table ``mv3dpose_crc32`` with one key per message (CRC32 of the
data, and of topic id and timestamp) and per topic record, which ros2 bag ignores. A corrupted
payload is then a ``BagError`` naming the file and the chunk (MCAP) or the message (sqlite3)
instead of wrong values; bags without CRCs (other writers) are read unchecked.
"""

from binascii import crc32
from pathlib import Path
import sqlite3
import struct
from typing import Callable, Iterable, Iterator, Optional, Tuple

from mv3dpose_ros.io.bag.files import BagError, MCAP_MAGIC, PathLike, storage_files
import numpy as np
from rosbags.rosbag2.storage_mcap import DECOMPRESSORS

CRC_TABLE = 'mv3dpose_crc32'
TOPIC_ROWS = 'SELECT id, name, type, serialization_format, offered_qos_profiles FROM topics'
U64 = struct.Struct('<Q')
_FOOTER = 29            # MCAP footer record: opcode, length, summary start, its offset, CRC


def unreadable(path: Path, exc: BaseException) -> BagError:
    """Return the ``BagError`` of a bag the library (rosbags, sqlite3) could not read."""
    reason = str(exc) or type(exc).__name__
    return BagError(f'{path}: not a readable rosbag2 bag (corrupt, truncated or incomplete): '
                    f'{reason}')


def _signed(key: int) -> int:
    return key - (1 << 64) if key >= 1 << 63 else key


def message_key(topic_id: int, timestamp: int, data: bytes) -> int:
    """Return the signed 64-bit integrity key of one sqlite3 message row."""
    where = crc32(struct.pack('<qq', int(timestamp), int(topic_id)))
    return _signed((crc32(bytes(data)) << 32) | where)


def topic_key(*row) -> int:
    """Return the integrity key of one ``topics`` row (id, name, type, format, QoS)."""
    text = '\x00'.join(str(v) for v in row).encode('utf-8', 'surrogateescape')
    return _signed((crc32(text) << 32) | crc32(b'mv3dpose topic row'))


def _check_topic_rows(where: Path, rows: Iterable[tuple], known: Callable[[int], bool]) -> None:
    for row in rows:
        if not known(topic_key(*row)):
            raise BagError(f'{where}: topic record {row[1]!r} fails its CRC (name, type or QoS '
                           'changed): the bag is corrupt')


def has_key(keys: np.ndarray, key: int) -> bool:
    """Tell whether the sorted ``keys`` hold ``key``."""
    i = int(np.searchsorted(keys, key))
    return i < len(keys) and keys[i] == key


def _read_only(db: Path) -> sqlite3.Connection:
    return sqlite3.connect(f'file:{db}?mode=ro', uri=True)


def _has_crc_table(conn: sqlite3.Connection) -> bool:
    return conn.execute('SELECT 1 FROM sqlite_master WHERE name = ?',
                        (CRC_TABLE,)).fetchone() is not None


def add_crc_table(db: Path) -> None:
    """Add the integrity key of every message of a finished sqlite3 bag."""
    with sqlite3.connect(db) as conn:
        conn.create_function('mv3dpose_key', 3, message_key, deterministic=True)
        conn.execute(f'CREATE TABLE {CRC_TABLE} (key INTEGER NOT NULL)')
        conn.execute(f'INSERT INTO {CRC_TABLE} SELECT mv3dpose_key(topic_id, timestamp, data) '
                     'FROM messages')
        conn.executemany(f'INSERT INTO {CRC_TABLE} VALUES (?)',
                         [(topic_key(*row),) for row in conn.execute(TOPIC_ROWS)])
    conn.close()


def sqlite_keys(path: Path) -> Optional[np.ndarray]:
    """
    Return the sorted integrity keys of a sqlite3 bag, or None if it has none.

    The topic records are checked here, the messages by the reader as it yields them.
    """
    dbs = [f for f in storage_files(path) if f.suffix == '.db3']
    if not dbs:
        return None
    keys = []
    try:
        for db in dbs:
            with _read_only(db) as conn:
                if not _has_crc_table(conn):
                    return None
                keys += [k for (k,) in conn.execute(f'SELECT key FROM {CRC_TABLE}')]
                topic_rows = list(conn.execute(TOPIC_ROWS))
    except sqlite3.Error as exc:
        raise unreadable(path, exc) from exc
    if not all(isinstance(k, int) for k in keys):
        raise BagError(f'{path}: table {CRC_TABLE} holds non-integer keys (corrupt)')
    keys = np.sort(np.array(keys, dtype=np.int64))
    _check_topic_rows(path, topic_rows, lambda key: has_key(keys, key))
    return keys


def _verify_sqlite(db: Path) -> Optional[int]:
    """Check every message row of a sqlite3 bag against its key; None if it has no keys."""
    try:
        with _read_only(db) as conn:
            if not _has_crc_table(conn):
                return None
            conn.create_function('mv3dpose_key', 3, message_key, deterministic=True)
            (rows,) = conn.execute('SELECT COUNT(*) FROM messages').fetchone()
            (keys,) = conn.execute(f'SELECT COUNT(*) FROM {CRC_TABLE}').fetchone()
            topic_rows = list(conn.execute(TOPIC_ROWS))
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
    _check_topic_rows(db, topic_rows, known.__contains__)
    if rows + len(topic_rows) != keys:
        raise BagError(f'{db}: {rows} message and {len(topic_rows)} topic rows but {keys} CRC '
                       'keys: rows were added or removed, the bag is corrupt')
    return rows


def mcap_summary_crc(path: Path) -> None:
    """Verify the footer's summary CRC of an MCAP file (when it has one)."""
    size = path.stat().st_size
    if size < len(MCAP_MAGIC) * 2 + _FOOTER:
        raise BagError(f'{path}: truncated MCAP file ({size} bytes)')
    with open(path, 'rb') as f:
        f.seek(size - 8 - _FOOTER)
        footer = f.read(_FOOTER)
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


def write_mcap_summary_crc(path: Path) -> None:
    """Fill in a finished MCAP file's summary CRC (what ``mcap_summary_crc`` checks)."""
    with open(path, 'r+b') as f:
        size = f.seek(0, 2)
        f.seek(size - 8 - _FOOTER + 9)
        start = U64.unpack(f.read(8))[0]
        f.seek(start)
        crc = crc32(f.read(size - 12 - start))
        f.seek(size - 12)
        f.write(struct.pack('<I', crc))


def mcap_records(f, start: int, end: int) -> Iterator[Tuple[int, int, bytes]]:
    """Yield ``(opcode, offset, body)`` of the records in ``[start, end)``; stop when short."""
    pos = start
    while pos + 9 <= end:
        f.seek(pos)
        head = f.read(9)
        op, length = head[0], U64.unpack_from(head, 1)[0]
        if length > end - pos - 9:
            return
        yield op, pos, f.read(length)
        pos += 9 + length


def chunk_records(body: bytes, path: Path, index: int, offset: int) -> bytes:
    """Return the uncompressed records of an MCAP chunk record; BagError if corrupt."""
    where = f'{path}: chunk {index} (at byte {offset})'
    try:
        _, _, usize, crc = struct.unpack_from('<QQQI', body, 0)
        (n,) = struct.unpack_from('<I', body, 28)
        compression = body[32:32 + n].decode()
        (clen,) = U64.unpack_from(body, 32 + n)
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
        for op, offset, body in mcap_records(f, len(MCAP_MAGIC), size):
            if op == 0x06:
                chunk_records(body, path, count, offset)
                count += 1
            elif op == 0x0F:   # DataEnd
                break
    return count


def verify_bag(path: PathLike) -> str:
    """
    Check the CRCs of every storage file of a bag (reads it all once); return a summary.

    Raises ``BagError`` naming the file and the chunk (MCAP) or message row (sqlite3).
    """
    done = []
    for f in storage_files(Path(path)):
        if f.suffix == '.mcap':
            mcap_summary_crc(f)
            done.append(f'{f.name}: {verify_mcap_chunks(f)} chunk CRCs verified')
        elif f.suffix == '.db3':
            n = _verify_sqlite(f)
            done.append(f'{f.name}: ' + (f'{n} message CRCs verified' if n is not None
                                         else 'no CRCs (written by another tool), unchecked'))
    return '; '.join(done) or 'no storage file'
