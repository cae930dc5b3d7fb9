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
not fit N-camera fusion. This one groups by integer-nanosecond header stamps and decides when
to stop waiting on the caller's *arrival* clock (the node's steady clock), so free-running
cameras whose inference finishes at different times lose no set:

* The *pivot* is the oldest buffered stamp. Each camera contributes its message nearest the
  pivot within ``[pivot, pivot + slop]``.
* A set is emitted as soon as every camera has contributed (complete). Otherwise it waits
  until ``max_wait`` has passed on the arrival clock since the first of its messages arrived,
  or until no missing camera can still contribute: by its observed frame period neither its
  next frame nor (when a later one already arrived) the frame before that falls in the
  window, e.g. a half-rate camera (a swapped pair of its own messages is still waited for),
  or it has been silent for longer than ``max_wait`` plus its period while its last stamp is
  more than ``max_wait`` before the pivot. Then it is emitted as a
  partial set when at least ``min_views`` cameras contributed, otherwise its messages are
  dropped (``counts.pivots_dropped``). ``poll(now)`` applies the wait when no message arrives.
* A camera may announce images it will send nothing for (``skip``: stamps strictly between
  two of its images, e.g. replaced by a newer image while its model was busy). A set waits
  for no camera whose announced gap holds its window, so it goes as soon as its last real
  message arrives instead of after ``max_wait``.
* The slop adapts to the cameras: each camera's frame period is the lower quartile of its
  recent stamp steps (robust to frames missing at random), and the slop used is at most
  half of the shortest period (a wider slop would merge consecutive frames of a camera and
  drop every other one). ``slop_s`` 0 means
  "half the frame period"; a configured ``slop_s`` wider than that is narrowed and
  ``slop_note`` says so (the node logs it naming the parameter ``sync.slop_s``).
* A message whose stamp is not newer than ``pivot + slop`` of the last decided pivot arrives
  too late for its set: it is counted as ``late`` and handed back (``AddResult.kind``), so
  the caller can still update its tracks with it (fusion_node does, ``Fusion.update_view``).
* The wait adapts to the rig: the arrival spread of each set's messages (arrival minus the
  arrival of the set's first message, on the arrival clock, late messages included) is kept
  for the recent messages, and the wait used is ``max(max_wait_s, 1.3 x p95 spread)``, at
  most ``max_wait_cap_s`` (a cap at or below ``max_wait_s`` keeps the wait fixed). Cameras
  whose inference finishes seconds apart on an overloaded host then lose no set, and a rig
  that keeps up waits no longer than ``max_wait_s``.
* Stamps more than ``jump_s`` away from the stream's time (the newest accepted stamp,
  advanced by the arrival time since) are *outliers*: held aside, and dropped and counted
  when the camera's next message is normal again. Only a sustained jump (``jump_confirm``
  consecutive outliers on each of at least two cameras, consistent with each other) is
  taken, and the held messages then continue the stream: backwards (a bag loop or a driver
  restart) the synchroniser is reset and the caller told so it can reset its tracker too;
  forwards (a pause, or input queues that dropped under load) time simply goes on.
* Losses upstream are counted from the stamps: a step longer than 1.5 of the camera's usual
  period counts the frames in between as ``lost`` (as ``skipped`` when the camera announced
  that gap).
* Memory is bounded: at most ``max_queue`` messages per camera (beyond it the oldest pivot is
  decided at once, counted as ``overflow``) and fixed windows for the statistics.

Its parts, one idea each: ``sync_window`` (the adaptive slop and wait), ``sync_outliers``
(the stream time, held outliers and sustained jumps), ``sync_stats`` (what ``stats`` and
``counts`` report to ``/diagnostics``).
"""

from bisect import insort
from collections import deque
from dataclasses import dataclass, field
import itertools
import math
import time
from typing import Any, Deque, Dict, List, Optional, Sequence, Tuple

from mv3dpose_ros.core.live.sync_outliers import StampOutliers
from mv3dpose_ros.core.live.sync_stats import CameraSyncStats, SyncCounts
from mv3dpose_ros.core.live.sync_window import AdaptiveSlop, AdaptiveWait
from mv3dpose_ros.core.types import NS_PER_S

#: Announced gaps kept per camera (only those around the pending sets matter).
GAP_WINDOW = 16


@dataclass
class SyncConfig:
    """Synchroniser parameters: stamps in message (header) time, waits in arrival time."""

    slop_s: float = 0.0              # max stamp distance from the set pivot [s]; 0 = half the
    #                                  observed frame period (a wider value is narrowed to it)
    max_wait_s: float = 0.1          # arrival time [s] a set waits for missing cameras after
    #                                  its first message arrived (covers inference skew)
    max_wait_cap_s: float = 0.25     # the latency budget: the wait adapts up to this (1.3 x
    #                                  p95 of the measured arrival spread of the sets); a
    #                                  message later than its set still updates the tracks
    #                                  (fusion.view_updates); <= max_wait_s: fixed wait
    min_views: int = 1               # partial sets with fewer cameras are dropped (1: a
    #                                  camera alone updates the tracks it sees when
    #                                  fusion.view_updates is on; otherwise 2 is used)
    max_queue: int = 30              # buffered messages per camera; beyond, the oldest set is
    #                                  decided at once (counted as overflow)
    jump_s: float = 0.5              # a stamp this far [s] from the stream time is an outlier
    jump_confirm: int = 3            # consecutive outliers per camera, on >= 2 cameras, that
    #                                  make a sustained jump (reset; e.g. a bag loop)
    stats_window: int = 100          # used messages kept per camera for offset / jitter
    offset_warn_fraction: float = 0.1   # warn when a camera's stamps stand this share of its
    #                                  frame period (and >= 5 ms) apart from the rest of the
    #                                  rig's, judged from arrival delays (a host clock that is
    #                                  off); 0 = off (also under sim time)
    stream_ahead_check: bool = True  # judge stamps ahead of the stream time on the arrival
    #                                  clock; off under sim time, where a paced or fast replay
    #                                  does not advance stamps at the arrival clock's rate (the
    #                                  node then compares stamps with /clock instead)

    def validate(self) -> None:
        """Raise ``ValueError`` naming the field when a value cannot work."""
        if not (math.isfinite(self.slop_s) and self.slop_s >= 0.0):
            raise ValueError(f'sync slop_s must be >= 0, got {self.slop_s}')
        if not (math.isfinite(self.max_wait_s) and self.max_wait_s >= 0.0):
            raise ValueError(f'sync max_wait_s must be >= 0, got {self.max_wait_s}')
        if not (math.isfinite(self.max_wait_cap_s) and self.max_wait_cap_s >= 0.0):
            raise ValueError(f'sync max_wait_cap_s must be >= 0, got {self.max_wait_cap_s}')
        if self.min_views < 1:
            raise ValueError(f'sync min_views must be >= 1, got {self.min_views}')
        if self.max_queue < 1:
            raise ValueError(f'sync max_queue must be >= 1, got {self.max_queue}')
        if not (math.isfinite(self.jump_s) and self.jump_s > 0.0):
            raise ValueError(f'sync jump_s must be > 0, got {self.jump_s}')
        if self.jump_confirm < 1:
            raise ValueError(f'sync jump_confirm must be >= 1, got {self.jump_confirm}')
        if self.stats_window < 1:
            raise ValueError(f'sync stats_window must be >= 1, got {self.stats_window}')
        if not (math.isfinite(self.offset_warn_fraction) and self.offset_warn_fraction >= 0.0):
            raise ValueError(f'sync offset_warn_fraction must be >= 0, got '
                             f'{self.offset_warn_fraction}')


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
    reason: str = ''                 # why the message was not accepted ('' when accepted)
    kind: str = ''                   # 'late' or 'outlier' when not accepted
    reset: bool = False              # a sustained jump reset the synchroniser


Entry = Tuple[int, int, int, Any]    # (stamp_ns, sequence, arrival_ns, message)


class StreamSynchronizer:
    """Group messages of N camera streams into sets by header stamp (see module docstring)."""

    def __init__(self, camera_ids: Sequence[str], config: Optional[SyncConfig] = None,
                 clock: Any = time.monotonic_ns) -> None:
        self.config = cfg = config or SyncConfig()
        cfg.validate()
        ids = list(camera_ids)
        if not ids:
            raise ValueError('StreamSynchronizer needs at least one camera id')
        if len(set(ids)) != len(ids):
            raise ValueError(f'duplicate camera ids in {ids}')
        self.camera_ids: Tuple[str, ...] = tuple(ids)
        self._clock = clock                          # arrival clock when add() gets no now_ns
        self._slop = AdaptiveSlop(cfg.slop_s)
        self._wait = AdaptiveWait(cfg.max_wait_s, cfg.max_wait_cap_s)
        self._outliers = StampOutliers(ids, cfg.jump_s, cfg.jump_confirm, cfg.max_queue,
                                       cfg.stream_ahead_check)
        self._seq = itertools.count()
        # Per camera, entries sorted by stamp.
        self._buffers: Dict[str, List[Entry]] = {c: [] for c in ids}
        #: Per camera counters and recent offsets (``/diagnostics``).
        self.stats: Dict[str, CameraSyncStats] = {
            c: CameraSyncStats(offsets_ns=deque(maxlen=cfg.stats_window)) for c in ids}
        #: The decisions over every camera (``/diagnostics``).
        self.counts = SyncCounts()
        self.last_emitted_ns: Optional[int] = None   # pivot of the last emitted set
        self._consumed_ns: Optional[int] = None      # stamps <= this are decided (emit/drop)
        self._first_arrival_ns: Optional[int] = None
        self._last_accepted_arrival: Dict[str, Optional[int]] = dict.fromkeys(ids)
        self._gaps: Dict[str, Deque[Tuple[int, int]]] = {
            c: deque(maxlen=GAP_WINDOW) for c in ids}

    @property
    def slop_ns(self) -> int:
        """Return the slop in use [ns]: stamps within it of a set's pivot join the set."""
        return self._slop.slop_ns

    @property
    def frame_period_ns(self) -> Optional[int]:
        """Return the shortest camera frame period seen now [ns] (None until known)."""
        return self._slop.frame_period_ns

    @property
    def slop_note(self) -> str:
        """Return why the configured slop was narrowed ('' while it was not)."""
        return self._slop.note

    @property
    def max_wait_ns(self) -> int:
        """
        Return the wait in use [ns].

        ``max(max_wait_s, 1.3 x spread_p95_s)``, at most ``max_wait_cap_s``: see the module
        docstring.
        """
        return self._wait.max_wait_ns

    @property
    def spread_p95_s(self) -> float:
        """Return the p95 arrival spread of the recent sets' messages [s] (NaN before any)."""
        return self._wait.spread_p95_s

    # --- public API ------------------------------------------------------------------------

    def add(self, camera_id: str, stamp_ns: int, msg: Any,
            now_ns: Optional[int] = None) -> AddResult:
        """
        Buffer one message that arrived at ``now_ns``; return the sets it let go (oldest first).

        ``now_ns`` is the arrival time on a monotonic clock (default: the constructor's
        ``clock``). Raises ``ValueError`` for an unknown camera id or a non-positive stamp:
        callers validate those first (they are configuration or driver errors, not timing).
        """
        if camera_id not in self._buffers:
            raise ValueError(f'unknown camera id {camera_id!r} (configured: '
                             f'{", ".join(self.camera_ids)})')
        stamp_ns = int(stamp_ns)
        if stamp_ns <= 0:
            raise ValueError(f'camera {camera_id!r}: stamp must be > 0, got {stamp_ns} ns')
        now = int(self._clock() if now_ns is None else now_ns)
        stats = self.stats[camera_id]
        stats.received += 1
        stats.last_arrival_ns = now
        if self._first_arrival_ns is None:
            self._first_arrival_ns = now
        entry = (stamp_ns, next(self._seq), now, msg)
        off = self._outliers.offset(stamp_ns, now, stats.last_seen_ns)
        if off is None:
            self._drop_outliers(camera_id)           # earlier outliers were isolated glitches
            return self._accept(camera_id, entry, now)
        pushed_out = self._outliers.hold(camera_id, entry)
        stats.dropped += pushed_out
        stats.outliers += pushed_out
        group = self._outliers.sustained_jump()
        if group:
            return self._restart(group, off, now)
        return AddResult(accepted=False, kind='outlier', reason=(
            f'camera {camera_id!r}: stamp {stamp_ns / NS_PER_S:.6f} s is {off / NS_PER_S:+.3f}'
            f' s from the stream time of the other messages (limit sync.jump_s '
            f'{self.config.jump_s:g} s); held aside and dropped unless it starts a sustained '
            f'jump on at least {self._outliers.cameras_needed} cameras (check the camera '
            'clocks)'))

    def observe(self, camera_id: str, stamp_ns: int) -> None:
        """Count a stamp the caller dropped before ``add`` (rate and gap statistics only)."""
        self.stats[camera_id].observe_step(int(stamp_ns), self._gaps[camera_id])

    def skip(self, camera_id: str, after_ns: int, before_ns: int,
             now_ns: Optional[int] = None) -> List[SyncedSet]:
        """
        Record that ``camera_id`` sends nothing stamped strictly between the two stamps.

        Returns the sets this lets go (those that waited only for that camera). Raises
        ``ValueError`` for an unknown camera or an empty interval.
        """
        if camera_id not in self._gaps:
            raise ValueError(f'unknown camera id {camera_id!r} (configured: '
                             f'{", ".join(self.camera_ids)})')
        after_ns, before_ns = int(after_ns), int(before_ns)
        if not 0 <= after_ns < before_ns:
            raise ValueError(f'camera {camera_id!r}: skipped images between '
                             f'{after_ns / NS_PER_S:.6f} s and {before_ns / NS_PER_S:.6f} s: '
                             'the interval must be 0 <= after < before')
        self._gaps[camera_id].append((after_ns, before_ns))
        return self.poll(now_ns)

    def poll(self, now_ns: Optional[int] = None) -> List[SyncedSet]:
        """Decide the sets whose wait has run out at ``now_ns`` (call it on a timer)."""
        return self._process(int(self._clock() if now_ns is None else now_ns))

    def flush(self) -> List[SyncedSet]:
        """Emit every buffered set that has ``min_views`` cameras (end of stream)."""
        return self._process(0, flush=True)

    def decide_through(self, stamp_ns: int) -> None:
        """Treat every stamp up to ``stamp_ns`` as decided (later arrivals are 'late')."""
        if self._consumed_ns is None or stamp_ns > self._consumed_ns:
            self._drop_through(int(stamp_ns), 'late')

    def reset(self) -> None:
        """Clear buffers, held outliers and the decided-set memory; counters are kept."""
        for cam in self.camera_ids:
            st = self.stats[cam]
            st.dropped += len(self._buffers[cam])
            self._buffers[cam].clear()
            self._drop_outliers(cam)
            st.latest_stamp_ns = st.last_seen_ns = None
        self.last_emitted_ns = None
        self._consumed_ns = None
        self._outliers.forget_time()
        self._wait.forget_sets()                     # stamps start again; spreads are kept
        for gaps in self._gaps.values():
            gaps.clear()
        self.counts.resets += 1

    def pending(self) -> int:
        """Return the number of buffered messages over all cameras (outliers excluded)."""
        return sum(len(b) for b in self._buffers.values())

    def oldest_pending_ns(self) -> Optional[int]:
        """Stamp of the oldest buffered message, None when empty."""
        heads = [b[0][0] for b in self._buffers.values() if b]
        return min(heads) if heads else None

    def next_decision_ns(self, now_ns: int) -> Optional[int]:
        """
        Return when (arrival clock, after ``now_ns``) ``poll`` may next let a set go.

        None when nothing is pending. Call it after a ``poll`` at ``now_ns`` (``add`` does not
        decide sets after a late message, whose stamp may still complete the picture): until
        the time returned, ``poll`` decides nothing more without a new message, as the oldest
        pending set waits until ``max_wait_ns`` after its first message, or until a camera
        missing from it has been silent long enough (see ``_may_still_come``). A caller may
        sleep until then instead of polling on a short timer; the time may be early (``poll``
        then decides nothing), never late.
        """
        pivot = self.oldest_pending_ns()
        if pivot is None:
            return None
        chosen, first = self._candidates(pivot)
        wait = self.max_wait_ns
        due = [first + wait]
        for cam in self.camera_ids:
            if cam not in chosen:
                last = self._last_accepted_arrival[cam]
                if last is None:
                    last = self._first_arrival_ns or now_ns
                due.append(last + wait + (self.stats[cam].period_ns or 0) + 1)
        future = [t for t in due if t > now_ns]
        return min(future) if future else now_ns

    @property
    def held_outliers(self) -> int:
        """Return the number of outlier messages held aside now."""
        return self._outliers.held

    # --- internals -------------------------------------------------------------------------

    def _drop_outliers(self, cam: str) -> None:
        n = self._outliers.drop(cam)
        self.stats[cam].dropped += n
        self.stats[cam].outliers += n

    def _restart(self, group: List[str], off: int, now: int) -> AddResult:
        """
        Take a sustained jump; replay the held messages (the group's first).

        Backwards (bag loop, driver restart, clock step back) the synchroniser is reset and
        the caller is told to reset its tracker. Forwards (the whole rig skipped ahead: a
        pause, or an overloaded node whose input queues dropped their oldest messages) time
        simply goes on: the stream time moves to the new stamps and nothing is reset.
        """
        held = self._outliers.take()
        what = (f'stamps of cameras {", ".join(group)} jumped {off / NS_PER_S:+.3f} s for '
                f'{self.config.jump_confirm}+ messages each')
        if off < 0:
            self.reset()
            result = AddResult(reset=True, reason=f'{what} (bag loop, driver restart or clock '
                               'step back); synchroniser reset')
        else:
            self._outliers.forget_time()
            self.counts.forward_jumps += 1
            result = AddResult(reason=f'{what} (pause or input dropped under load); '
                               'continuing from the new stamps')
        order = sorted((e for c in group for e in ((c, x) for x in held[c])),
                       key=lambda ce: ce[1][1])
        order += sorted((e for c in self.camera_ids if c not in group
                         for e in ((c, x) for x in held[c])), key=lambda ce: ce[1][1])
        for c, entry in order:
            if self._outliers.offset(entry[0], now, self.stats[c].last_seen_ns) is None:
                result.sets.extend(self._accept(c, entry, now).sets)
            else:
                self._outliers.hold(c, entry)
        return result

    def _accept(self, cam: str, entry: Entry, now: int) -> AddResult:
        stamp_ns = entry[0]
        stats = self.stats[cam]
        self._last_accepted_arrival[cam] = entry[2]
        stats.observe_step(stamp_ns, self._gaps[cam])
        if stats.latest_stamp_ns is None or stamp_ns > stats.latest_stamp_ns:
            stats.latest_stamp_ns = stamp_ns
        self._slop.update(self.stats)
        if self._consumed_ns is not None and stamp_ns <= self._consumed_ns:
            stats.dropped += 1
            stats.late += 1
            self._wait.late(stamp_ns, entry[2])
            return AddResult(accepted=False, kind='late', reason=(
                f'camera {cam!r}: stamp {stamp_ns / NS_PER_S:.6f} s arrived after its set was '
                f'decided (sets up to {self._consumed_ns / NS_PER_S:.6f} s are emitted or '
                f'dropped; a camera this late needs a longer sync.max_wait_s)'))
        self._outliers.accepted(stamp_ns, entry[2])
        insort(self._buffers[cam], entry, key=lambda e: e[0])
        return AddResult(sets=self._process(now))

    def _candidates(self, pivot: int) -> Tuple[Dict[str, int], int]:
        """Return camera -> index of its message nearest ``pivot`` and their first arrival."""
        chosen = {}
        first = None
        hi = pivot + self.slop_ns
        for cam, buf in self._buffers.items():
            best = None
            for i, (stamp, _, _, _) in enumerate(buf):
                if stamp > hi:
                    break
                if stamp >= pivot and (best is None or stamp < buf[best][0]):
                    best = i
            if best is not None:
                chosen[cam] = best
                arrival = buf[best][2]
                first = arrival if first is None else min(first, arrival)
        return chosen, first if first is not None else 0

    def _may_still_come(self, chosen: Dict[str, int], pivot: int, now: int) -> Optional[str]:
        """
        Return None while a camera missing from the pivot's set can still send for it.

        Else why none can: 'skipped (announced)' when a camera's announced gap holds the
        window, else 'no camera can still come'.
        """
        slop, wait = self.slop_ns, self.max_wait_ns
        hi = pivot + slop
        reason = 'no camera can still come'
        for cam in self.camera_ids:
            if cam in chosen:
                continue
            if any(after < pivot and hi < before for after, before in self._gaps[cam]):
                reason = 'skipped (announced)'
                continue                             # it said it sends nothing in the window
            st = self.stats[cam]
            last_arrival = self._last_accepted_arrival[cam]
            if last_arrival is None:                 # nothing usable yet: silent since start
                last_arrival = self._first_arrival_ns
            period = st.period_ns or 0
            tol = min(period // 4, slop // 2)
            latest = st.latest_stamp_ns
            if latest is not None and latest > hi and (
                    not period or latest - period > hi or latest - period + tol < pivot):
                continue        # it sent a later frame, and the one before that is not ours
            if now - last_arrival > wait + period and (latest is None or (
                    period and latest < pivot - max(wait, period * 3 // 2))):
                continue     # silent: nothing for a while, and its last frame is long past
                #              (a node stalled by the CPU sees every camera late, not silent;
                #              at a slow set rate whose delay varies, the camera's previous
                #              frame is one period back: it is not silent before it skips one;
                #              before its period is known, e.g. the first sets of a replay
                #              paced by slow inference, it is waited for)
            if period and latest is not None and latest < pivot and \
                    latest + period - tol > hi:
                continue                             # its next frame falls after the window
            return None
        return reason

    def _process(self, now: int, flush: bool = False) -> List[SyncedSet]:
        """Emit or drop pivots while they are decided; ``flush`` decides everything."""
        out = []
        counts = self.counts
        while True:
            pivot = self.oldest_pending_ns()
            if pivot is None:
                return out
            chosen, first_arrival = self._candidates(pivot)
            if len(chosen) < len(self.camera_ids) and not flush:
                if any(len(b) > self.config.max_queue for b in self._buffers.values()):
                    counts.overflow_decisions += 1
                    counts.decisions['queue full'] += 1
                elif now - first_arrival >= self.max_wait_ns:
                    counts.decisions['waited max_wait'] += 1
                else:
                    why = self._may_still_come(chosen, pivot, now)
                    if why is None:
                        return out
                    counts.decisions[why] += 1
            if not flush:
                self._wait.decided(pivot, pivot + self.slop_ns, first_arrival,
                                   [self._buffers[c][i][2] for c, i in chosen.items()])
            if len(chosen) >= self.config.min_views:
                out.append(self._emit(pivot, chosen))
            else:
                self._drop_through(pivot + self.slop_ns, 'too_few_views')
                counts.pivots_dropped += 1

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
        self._drop_through(pivot + self.slop_ns, 'duplicates')
        self.last_emitted_ns = pivot
        self.counts.sets_emitted += 1
        if missing:
            self.counts.partial_sets += 1
        return SyncedSet(stamp_ns=stamp, messages={c: e[3] for c, e in members.items()},
                         stamps_ns=stamps, missing=missing)

    def _drop_through(self, limit_ns: int, reason: str) -> None:
        """Drop (and count) buffered messages with stamp <= ``limit_ns``; later ones are late."""
        self._consumed_ns = limit_ns
        for cam, buf in self._buffers.items():
            n = 0
            while n < len(buf) and buf[n][0] <= limit_ns:
                n += 1
            if n:
                del buf[:n]
                st = self.stats[cam]
                st.dropped += n
                st.unmatched[reason] += n
