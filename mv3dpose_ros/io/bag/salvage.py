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
``salvage``: the intact messages of an interrupted recording, as a new complete bag.

What ``mv3dpose bag recover`` runs on a ``.NAME.partial-PID`` directory left by a killed
``BagWriter``: MCAP records are read up to the first one that is cut or fails its CRC,
sqlite3 keeps every committed row.
"""

from pathlib import Path
import sqlite3
import struct
from typing import Dict, List, NamedTuple, Tuple

from mv3dpose_ros.io.bag.crc import chunk_records, mcap_records, U64
from mv3dpose_ros.io.bag.files import BagError, MCAP_MAGIC, PathLike
from mv3dpose_ros.io.bag.writer import BagWriter
from rosbags.rosbag2.metadata import parse_qos


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

        for op, offset, body in mcap_records(f, len(MCAP_MAGIC), size):
            try:
                if op == 0x06:
                    raw = chunk_records(body, path, index, offset)
                    index += 1
                    pos = 0
                    while pos + 9 <= len(raw):
                        iop, ilen = raw[pos], U64.unpack_from(raw, pos + 1)[0]
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
