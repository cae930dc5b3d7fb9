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
``BagWriter``: standard rosbag2 v9 bags, written atomically and with checkpoints.

The bag is written into a hidden ``.NAME.partial-PID`` directory beside the target and renamed
into place only when closed without error: an interrupted or failed write never leaves a bag
that looks complete. ``checkpoint`` closes the pending MCAP chunk and flushes it (sqlite3:
commits), so a writer killed with SIGKILL leaves a partial directory in which everything up to
the last checkpoint is intact (``partial_dirs`` finds them, ``salvage`` completes them). A
writer holds a ``flock`` on ``writer.lock`` in its directory while it writes, so that
``writer_alive`` tells a running writer (this process's own included) from a dead one whose
PID another process may have taken since. MCAP chunks and summary get their CRCs, sqlite3 bags
their key table (``crc``).
"""

from binascii import crc32
import fcntl
import os
from pathlib import Path
import shutil
import struct
from typing import Any, Dict, List, Optional, Sequence

from mv3dpose_ros.io.bag.crc import add_crc_table, write_mcap_summary_crc
from mv3dpose_ros.io.bag.files import BagError, check_replaceable, DEFAULT_STORAGE, PathLike
from mv3dpose_ros.io.bag.files import STORAGES
from mv3dpose_ros.io.bag.typestore import get_typestore, normalise_type, serialize
from rosbags.interfaces import Qos
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.storage_mcap import McapWriter
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Writer

_PLUGINS = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}


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
        write_mcap_summary_crc(self.path)


class _CheckpointSqlite3Writer(Sqlite3Writer):
    """rosbags' sqlite3 writer with checkpoints (commits)."""

    def checkpoint(self) -> None:
        """Commit what was written so far."""
        self.conn.commit()


class _Writer(Writer):
    STORAGE_PLUGINS = {StoragePlugin.MCAP: _CrcMcapWriter,
                       StoragePlugin.SQLITE3: _CheckpointSqlite3Writer}


def _partial_dir(path: Path, pid: Any) -> Path:
    """Return the hidden directory a writer of ``path`` in process ``pid`` writes into."""
    return path.parent / f'.{path.name}.partial-{pid}'


#: The file in a partial directory that its writer holds an exclusive ``flock`` on while it
#: writes: the kernel drops the lock when the process dies (SIGKILL included), so a lock that
#: can be taken means a dead writer, whatever process now has its PID.
LOCK_NAME = 'writer.lock'


def writer_alive(partial: PathLike) -> bool:
    """
    Tell whether the writer of a ``.NAME.partial-PID`` directory is still running.

    Its lock (``LOCK_NAME``) decides: held means alive, this process's own writers included.
    A directory without one (a writer of an older version, or one caught between creating the
    directory and its lock) is alive while process PID exists, and always when PID is this
    process.
    """
    d = Path(partial)
    try:
        fd = os.open(d / LOCK_NAME, os.O_RDONLY)
    except FileNotFoundError:
        pid = d.name.rsplit('-', 1)[-1]
        if not pid.isdigit():
            return False
        if int(pid) == os.getpid():
            return True
        try:
            os.kill(int(pid), 0)
        except ProcessLookupError:
            return False
        except PermissionError:
            return True
        return True
    except OSError:
        return True     # cannot tell (no read permission): leave it alone
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return True
    finally:
        os.close(fd)    # releases the lock if this took it
    return False


def partial_dirs(path: PathLike) -> List[Path]:
    """Return the ``.NAME.partial-PID`` directories of ``path`` left by dead writers."""
    target = Path(path)
    found = []
    for d in sorted(target.parent.glob(_partial_dir(target, '*').name)):
        pid = d.name.rsplit('-', 1)[-1]
        if pid.isdigit() and d.is_dir() and not writer_alive(d):
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
        check_replaceable(self.path)
        parent = self.path.parent
        if not parent.is_dir():
            raise BagError(f'{self.path}: output folder {parent} does not exist')
        self._tmp_root = _partial_dir(self.path, os.getpid())
        shutil.rmtree(self._tmp_root, ignore_errors=True)
        self._tmp_root.mkdir()
        self._lock = os.open(self._tmp_root / LOCK_NAME, os.O_RDWR | os.O_CREAT, 0o644)
        fcntl.flock(self._lock, fcntl.LOCK_EX | fcntl.LOCK_NB)   # held until close / abort
        try:
            self._writer = _Writer(self._tmp_root / self.path.name, version=9,
                                   storage_plugin=_PLUGINS[storage])
            self._writer.open()
        except BaseException:
            shutil.rmtree(self._tmp_root, ignore_errors=True)
            self._release_lock()
            raise
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
                add_crc_table(db)
            if self.path.exists():
                if not self.overwrite:
                    raise BagError(f'{self.path}: appeared while writing; not overwriting it')
                check_replaceable(self.path)
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
            self._release_lock()
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
        self._release_lock()

    def _release_lock(self) -> None:
        if self._lock is not None:
            os.close(self._lock)
            self._lock = None
