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
Fast DDS shared-memory files left in /dev/shm by processes that are gone (no rclpy).

Each Fast DDS participant with shared memory creates a segment ``fastrtps_<16 hex>`` (64 MB
with ``config/fastdds_shm.xml``) and a lock file ``<segment>_el`` that it holds locked
(``flock``) while it lives; its ports ``fastrtps_port<N>`` have lock files ``_el`` / ``_sl``
and a semaphore ``sem.fastrtps_port<N>_mutex``. A process that exits cleanly removes its
files; one that is killed (SIGKILL, a crash, an out-of-memory kill) leaves them, and nothing
in the PyPI wheels removes them (Fast DDS's ``fastdds shm clean`` is not there). A rig whose
nodes crash and respawn would fill /dev/shm (64 MB in Docker by default), after which new
processes fall back to UDP and lose HD images. ``clean_stale_files`` removes the files of
segments and ports none of whose locks anybody holds (as ``fastdds shm clean`` does, which
judges each lock file alone), and only lock files older than ``min_age_s``, so a process that
has just created its segment and not yet locked it keeps it.
"""

import fcntl
import os
import re
import time
from typing import Dict, List, Mapping, Optional, Tuple

SHM_DIR = '/dev/shm'
#: lock files younger than this are left alone (their owner may be about to lock them)
MIN_AGE_S = 10.0
_SEGMENT_LOCK = re.compile(r'^fastrtps_[0-9a-z]{16}_(el|sl)$')
_PORT_LOCK = re.compile(r'^fastrtps_port\d{1,5}_(el|sl)$')
FAST_DDS_RMWS = ('', 'rmw_fastrtps_cpp', 'rmw_fastrtps_dynamic_cpp')


def uses_fast_dds(environ: Mapping[str, str] = os.environ) -> bool:
    """Tell whether ROS processes started with ``environ`` use Fast DDS (Jazzy's default)."""
    return environ.get('RMW_IMPLEMENTATION', '').strip() in FAST_DDS_RMWS


def is_locked(path: str) -> bool:
    """Tell whether some process may hold a lock on ``path`` (missing: no; unreadable: yes)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except FileNotFoundError:
        return False
    except OSError:
        return True                                  # cannot tell: keep it
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        return True
    finally:
        os.close(fd)                                       # also releases our probe lock
    return False


def stale_files(shm_dir: str = SHM_DIR, min_age_s: float = MIN_AGE_S,
                now_s: Optional[float] = None) -> List[str]:
    """
    Return the paths of Fast DDS segment and port files whose owners are all gone.

    A segment or port is stale when none of its lock files (``_el``, ``_sl``) is held and all
    are older than ``min_age_s``; its lock files, the segment and, for a port, the semaphore
    are returned.
    """
    try:
        names = os.listdir(shm_dir)
    except OSError:
        return []
    now_s = time.time() if now_s is None else now_s
    locks: Dict[str, List[str]] = {}
    for name in sorted(names):
        if _SEGMENT_LOCK.match(name) or _PORT_LOCK.match(name):
            locks.setdefault(name[:-3], []).append(os.path.join(shm_dir, name))
    out: List[str] = []
    for base, paths in locks.items():
        try:
            if any(now_s - os.stat(p).st_mtime < min_age_s for p in paths):
                continue
        except OSError:
            continue
        if any(is_locked(p) for p in paths):
            continue
        out += paths + [os.path.join(shm_dir, base)]
        if base.startswith('fastrtps_port'):
            out.append(os.path.join(shm_dir, f'sem.{base}_mutex'))
    return out


def clean_stale_files(shm_dir: str = SHM_DIR, min_age_s: float = MIN_AGE_S) -> Tuple[int, int]:
    """Remove the stale files of ``stale_files``; return (files removed, bytes freed)."""
    removed = freed = 0
    for path in stale_files(shm_dir, min_age_s):
        try:
            size = os.stat(path).st_size
            os.remove(path)
        except OSError:
            continue                                 # gone already, or not ours to remove
        removed += 1
        freed += size
    return removed, freed
