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
N-stream synchroniser: groups per-camera messages by capture stamp (no rclpy).

``message_filters.ApproximateTimeSynchronizer`` searches all combinations (exponential in the
number of cameras), never emits a set with a camera missing and reports no drops, so it does
not fit N-camera fusion. This one works on integer-nanosecond header stamps only (never wall
time), so replaying a bag at any rate gives the same sets:

* The *pivot* is the oldest buffered stamp. Each camera contributes its message nearest the
  pivot within ``[pivot, pivot + slop]``.
* A set is emitted as soon as every camera has contributed (complete), or, once the stream
  *horizon* has passed ``pivot + max_wait``, as a partial set when at least ``min_views``
  cameras contributed (otherwise the pivot's messages are dropped).
* The horizon is the second-newest per-camera latest stamp (the newest with one camera or
  ``min_views`` 1), so a single camera with a bogus future stamp cannot flush everybody's
  buffers, while a set that needs only one view can still expire.
* A message whose stamp is not newer than ``pivot + slop`` of the last emitted (or dropped)
  pivot arrives too late for its set: it is dropped and counted as ``late``.
* A camera whose own stamps jump backwards by more than ``backward_jump_s`` (bag loop, driver
  restart) resets the synchroniser; the caller is told so it can reset its tracker too.
* Memory is bounded: at most ``max_queue`` messages per camera (oldest dropped first) and a
  fixed window of offsets for the statistics.
"""

from bisect import insort
from collections import deque
from dataclasses import dataclass, field
import itertools
import math
from typing import Any, Deque, Dict, Iterable, List, Optional, Sequence, Tuple

NS_PER_S = 1_000_000_000


@dataclass
class SyncConfig:
    """Synchroniser parameters; times in seconds of message (header) time."""

    slop_s: float = 0.017            # max stamp distance from the pivot (≈ 0.5 / fps)
    max_wait_s: float = 0.1          # message time to wait for missing cameras
    min_views: int = 2               # partial sets with fewer cameras are dropped
    max_queue: int = 30              # per-camera buffer bound (messages)
    backward_jump_s: float = 0.5     # a camera's stamps going back this much resets everything
    stats_window: int = 100          # used messages kept per camera for offset / jitter

    def validate(self) -> None:
        """Raise ``ValueError`` naming the field when a value cannot work."""
        if not (math.isfinite(self.slop_s) and self.slop_s >= 0.0):
            raise ValueError(f'sync slop_s must be >= 0, got {self.slop_s}')
        if not (math.isfinite(self.max_wait_s) and self.max_wait_s >= 0.0):
            raise ValueError(f'sync max_wait_s must be >= 0, got {self.max_wait_s}')
        if self.min_views < 1:
            raise ValueError(f'sync min_views must be >= 1, got {self.min_views}')
        if self.max_queue < 1:
            raise ValueError(f'sync max_queue must be >= 1, got {self.max_queue}')
        if not self.backward_jump_s > 0.0:
            raise ValueError(f'sync backward_jump_s must be > 0, got {self.backward_jump_s}')
        if self.stats_window < 1:
            raise ValueError(f'sync stats_window must be >= 1, got {self.stats_window}')


@dataclass
class SyncedSet:
    """One synchronised set: at most one message per camera."""

    stamp_ns: int                    # mean of the members' stamps
    messages: Dict[str, Any]         # camera id -> message
    stamps_ns: Dict[str, int]        # camera id -> its header stamp
    missing: Tuple[str, ...]         # configured cameras without a message in this set

    @property
    def stamp(self) -> float:
        """Set stamp in seconds."""
        return self.stamp_ns / NS_PER_S

    @property
    def complete(self) -> bool:
        """Whether every configured camera contributed."""
        return not self.missing


@dataclass
class AddResult:
    """What one ``add`` did: the sets it completed and whether the message was accepted."""

    sets: List[SyncedSet] = field(default_factory=list)
    accepted: bool = True
    reason: str = ''                 # why the message was rejected ('' when accepted)
    reset: bool = False              # the synchroniser was reset before adding the message


@dataclass
class CameraSyncStats:
    """Per-camera counters (since construction; ``reset`` keeps them) and recent offsets."""

    received: int = 0                # messages passed to ``add``
    used: int = 0                    # messages emitted in a set
    dropped: int = 0                 # messages discarded unused (all reasons, incl. late)
    late: int = 0                    # ... of which arrived after their set was emitted
    missing: int = 0                 # emitted sets without this camera
    latest_stamp_ns: Optional[int] = None
    offsets_ns: Deque[int] = field(default_factory=deque)  # stamp - set stamp, recent used

    @property
    def offset_mean_s(self) -> float:
        """Mean offset of this camera's stamps to the set stamps (NaN before any use)."""
        if not self.offsets_ns:
            return math.nan
        return sum(self.offsets_ns) / len(self.offsets_ns) / NS_PER_S

    @property
    def offset_jitter_s(self) -> float:
        """Return the standard deviation of the offsets (NaN before any use)."""
        n = len(self.offsets_ns)
        if n == 0:
            return math.nan
        mean = sum(self.offsets_ns) / n
        return math.sqrt(sum((o - mean) ** 2 for o in self.offsets_ns) / n) / NS_PER_S


class StreamSynchronizer:
    """Group messages of N camera streams into sets by header stamp (see module docstring)."""

    def __init__(self, camera_ids: Sequence[str], config: Optional[SyncConfig] = None) -> None:
        self.config = config or SyncConfig()
        self.config.validate()
        ids = list(camera_ids)
        if not ids:
            raise ValueError('StreamSynchronizer needs at least one camera id')
        if len(set(ids)) != len(ids):
            raise ValueError(f'duplicate camera ids in {ids}')
        self.camera_ids: Tuple[str, ...] = tuple(ids)
        self._slop = int(round(self.config.slop_s * NS_PER_S))
        self._max_wait = int(round(self.config.max_wait_s * NS_PER_S))
        self._jump = int(round(self.config.backward_jump_s * NS_PER_S))
        self._seq = itertools.count()
        # Per camera, a list of (stamp_ns, seq, message) sorted by stamp.
        self._buffers: Dict[str, List[Tuple[int, int, Any]]] = {c: [] for c in ids}
        self.stats: Dict[str, CameraSyncStats] = {
            c: CameraSyncStats(offsets_ns=deque(maxlen=self.config.stats_window)) for c in ids}
        self.last_emitted_ns: Optional[int] = None   # pivot of the last emitted set
        self._consumed_ns: Optional[int] = None      # stamps <= this are decided (emit/drop)
        self.sets_emitted = 0
        self.partial_sets = 0
        self.pivots_dropped = 0                      # expired pivots with < min_views cameras
        self.resets = 0

    # --- public API ------------------------------------------------------------------------

    def add(self, camera_id: str, stamp_ns: int, msg: Any) -> AddResult:
        """
        Buffer one message; return the sets it completed (oldest first).

        Raises ``ValueError`` for an unknown camera id or a non-positive stamp: callers
        validate those first (they are configuration or driver errors, not timing).
        """
        if camera_id not in self._buffers:
            raise ValueError(f'unknown camera id {camera_id!r} (configured: '
                             f'{", ".join(self.camera_ids)})')
        stamp_ns = int(stamp_ns)
        if stamp_ns <= 0:
            raise ValueError(f'camera {camera_id!r}: stamp must be > 0, got {stamp_ns} ns')
        result = AddResult()
        stats = self.stats[camera_id]
        if stats.latest_stamp_ns is not None and stamp_ns < stats.latest_stamp_ns - self._jump:
            back = (stats.latest_stamp_ns - stamp_ns) / NS_PER_S
            self.reset()
            result.reset = True
            result.reason = (f'camera {camera_id!r}: stamp jumped back {back:.3f} s; '
                             f'synchroniser reset')
        stats.received += 1
        if self._consumed_ns is not None and stamp_ns <= self._consumed_ns:
            stats.dropped += 1
            stats.late += 1
            result.accepted = False
            result.reason = (f'camera {camera_id!r}: stamp {stamp_ns / NS_PER_S:.6f} s arrived '
                             f'after its set was decided (sets up to '
                             f'{self._consumed_ns / NS_PER_S:.6f} s are emitted or dropped)')
            return result
        if stats.latest_stamp_ns is None or stamp_ns > stats.latest_stamp_ns:
            stats.latest_stamp_ns = stamp_ns
        buf = self._buffers[camera_id]
        insort(buf, (stamp_ns, next(self._seq), msg), key=lambda e: e[0])
        if len(buf) > self.config.max_queue:
            buf.pop(0)
            stats.dropped += 1
        result.sets = self._process(self._horizon())
        return result

    def flush(self) -> List[SyncedSet]:
        """Emit every buffered set that has ``min_views`` cameras (end of stream)."""
        return self._process(None)

    def reset(self) -> None:
        """Clear buffers and the emitted-set memory; counters are kept (they are totals)."""
        for cam, buf in self._buffers.items():
            self.stats[cam].dropped += len(buf)
            buf.clear()
            self.stats[cam].latest_stamp_ns = None
        self.last_emitted_ns = None
        self._consumed_ns = None
        self.resets += 1

    def pending(self) -> int:
        """Return the number of buffered messages over all cameras."""
        return sum(len(b) for b in self._buffers.values())

    def oldest_pending_ns(self) -> Optional[int]:
        """Stamp of the oldest buffered message, None when empty."""
        heads = [b[0][0] for b in self._buffers.values() if b]
        return min(heads) if heads else None

    # --- internals -------------------------------------------------------------------------

    def _horizon(self) -> Optional[int]:
        latest = sorted((s.latest_stamp_ns for s in self.stats.values()
                         if s.latest_stamp_ns is not None), reverse=True)
        if not latest:
            return None
        k = min(len(latest), 2, self.config.min_views)
        return latest[k - 1]

    def _candidates(self, pivot: int) -> Dict[str, int]:
        """Return camera -> index of its message nearest ``pivot`` within the slop window."""
        chosen = {}
        hi = pivot + self._slop
        for cam, buf in self._buffers.items():
            best = None
            for i, (stamp, _, _) in enumerate(buf):
                if stamp > hi:
                    break
                if stamp >= pivot and (best is None or stamp - pivot < buf[best][0] - pivot):
                    best = i
            if best is not None:
                chosen[cam] = best
        return chosen

    def _process(self, horizon: Optional[int]) -> List[SyncedSet]:
        """Emit or drop pivots while possible; ``horizon`` None means flush everything."""
        out = []
        while True:
            pivot = self.oldest_pending_ns()
            if pivot is None:
                return out
            chosen = self._candidates(pivot)
            complete = len(chosen) == len(self.camera_ids)
            expired = horizon is None or horizon > pivot + self._max_wait
            if not (complete or expired):
                return out
            if len(chosen) >= self.config.min_views:
                out.append(self._emit(pivot, chosen))
            else:
                self._drop_through(pivot + self._slop)
                self.pivots_dropped += 1

    def _emit(self, pivot: int, chosen: Dict[str, int]) -> SyncedSet:
        members = {cam: self._buffers[cam][i] for cam, i in chosen.items()}
        for cam, i in chosen.items():
            del self._buffers[cam][i]
        stamps = {cam: e[0] for cam, e in members.items()}
        stamp = sum(stamps.values()) // len(stamps)
        missing = tuple(c for c in self.camera_ids if c not in members)
        for cam in self.camera_ids:
            st = self.stats[cam]
            if cam in members:
                st.used += 1
                st.offsets_ns.append(stamps[cam] - stamp)
            else:
                st.missing += 1
        self._drop_through(pivot + self._slop)
        self.last_emitted_ns = pivot
        self.sets_emitted += 1
        if missing:
            self.partial_sets += 1
        return SyncedSet(stamp_ns=stamp, messages={c: e[2] for c, e in members.items()},
                         stamps_ns=stamps, missing=missing)

    def _drop_through(self, limit_ns: int) -> None:
        """Drop (and count) buffered messages with stamp <= ``limit_ns``; later ones are late."""
        self._consumed_ns = limit_ns
        for cam, buf in self._buffers.items():
            n = 0
            while n < len(buf) and buf[n][0] <= limit_ns:
                n += 1
            if n:
                del buf[:n]
                self.stats[cam].dropped += n


def summarize(stats: Dict[str, CameraSyncStats], cameras: Iterable[str]) -> Dict[str, dict]:
    """Return plain-dict statistics per camera (for logs and diagnostics)."""
    return {c: {'received': stats[c].received, 'used': stats[c].used,
                'dropped': stats[c].dropped, 'late': stats[c].late,
                'missing': stats[c].missing, 'offset_mean_s': stats[c].offset_mean_s,
                'offset_jitter_s': stats[c].offset_jitter_s} for c in cameras}
