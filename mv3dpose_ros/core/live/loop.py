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
The live fusion loop without ROS: what ``fusion_node`` publishes, given what arrives when.

``LiveFusion`` owns the N-stream synchroniser (``core.live.sync``), ``Fusion`` and the publication
policy (``core.live.output.LiveOutput``), and the rules between them that a live stream needs:

* each synchronised set goes through ``Fusion.step``; a message late for its set updates the
  tracks at its own stamp (``Fusion.update_view``) when ``fusion.view_updates`` is on;
* tracks coast at least ``COAST_SET_PERIODS`` set periods (median of the recent set stamp
  steps) beyond ``fusion.max_coast_s`` when sets come slower (an overloaded rig);
* once no set and no input came for ``max_coast_s``, ``idle_step`` ages the tracks with empty
  steps, so they go COASTING and are DELETED as with empty sets;
* after each set, the calibration watch (``core.selfcal.watch``) compares every camera's pose
  with where the others put the people; a camera it names is left out of the sets (modes
  exclude and correct) and, in mode correct, turned back into the rig
  (``CalibrationWatch.fused``; ``LiveLog.rig`` hears of every such change);
* ``reset`` (the node clock jumped back, ``~/reset``, a sustained stamp jump found by the
  synchroniser) clears synchroniser and tracks and publishes the tombstones of the published
  tracks; a failing ``Fusion.step`` resets the tracks and is counted.

Time is passed in, never read: ``now_ns`` is the steady (arrival) clock the synchroniser waits
on, ``clock_ns`` the node clock (ROS time: sim time under a replay). Every call returns the
``Publication`` s it produced, in order: ``~/tracks`` sets (public ids) and, with a lag,
``~/tracks_smoothed`` sets. ``mv3dpose track --smooth causal`` / ``fixed-lag`` feeds its
frames to ``step_set`` of this same object, so offline equals live by construction.
"""

from collections import Counter, deque
from dataclasses import dataclass, field
import logging
import time
from typing import Any, Callable, Deque, List, Mapping, Optional, Sequence

from mv3dpose_ros.core.fusion.pipeline import Fusion, FusionConfig
from mv3dpose_ros.core.live.clock_offsets import ClockCheck
from mv3dpose_ros.core.live.output import LiveOutput
from mv3dpose_ros.core.live.sync import StreamSynchronizer, SyncConfig, SyncedSet
from mv3dpose_ros.core.selfcal.watch import CalibrationWatch, WatchConfig, WatchEvent
from mv3dpose_ros.core.skeleton import get_layout
from mv3dpose_ros.core.types import NS_PER_S, Track, TrackState
import numpy as np

LOG = logging.getLogger('mv3dpose_ros.live')

#: Longest stretch [ns] empty steps may cover after the last set (tracks are long deleted by
#: then; a node clock that jumped further must not produce absurd stamps).
MAX_IDLE_SPAN_NS = 3600 * NS_PER_S
#: Period [s] of the empty steps that age the tracks once no input set arrives.
IDLE_STEP_S = 0.1
#: Tracks coast at least this many set periods (median of the recent set stamp steps), beyond
#: fusion.max_coast_s when sets come slower: an overloaded rig's inference grid (pose2d
#: inference_rate_hz auto) may give a set every 1-3 s, and its people must keep their tracks.
COAST_SET_PERIODS = 2.5


@dataclass
class Publication:
    """One set to publish: on ``~/tracks``, or on ``~/tracks_smoothed`` when ``smoothed``."""

    stamp_ns: int                    # the set's capture stamp (its header stamp)
    stamp: float                     # the same in seconds, as given to Fusion.step
    tracks: List[Track]              # public ids
    smoothed: bool = False
    latency: bool = True             # a capture -> publish latency to count (not idle steps)
    processing_s: Optional[float] = None   # Fusion.step time of a real set


@dataclass
class Intake:
    """What ``add`` did with one message."""

    accepted: bool                   # taken by the synchroniser
    kind: str = ''                   # 'late' or 'outlier' when not accepted
    reason: str = ''                 # why not accepted, or a forward jump that was taken
    reset: bool = False              # a sustained stamp jump reset synchroniser and tracks
    late_used: bool = False          # late, and it updated tracks at its stamp
    late_refused: bool = False       # late, with fusion.view_updates off: dropped
    publications: List[Publication] = field(default_factory=list)


@dataclass
class LiveLog:
    """Where the live loop's messages go (Python logging unless the node passes its logger)."""

    info: Callable[[str], None] = LOG.info
    warning: Callable[[str], None] = LOG.warning
    throttled: Callable[[str, str], None] = lambda key, text: LOG.warning(text)  # key, text
    #: The rig in use changed (the calibration watch corrected a camera): every camera.
    rig: Callable[[Mapping[str, Any]], None] = lambda cameras: None


class LiveFusion:
    """Synchroniser, ``Fusion`` and publication policy of one live stream (no ROS, no clock)."""

    def __init__(self, camera_ids: Sequence[str], layout: Any, sync_config: SyncConfig,
                 fusion_config: FusionConfig, publish_tentative: bool = False, lag: int = 0,
                 log: Optional[LiveLog] = None,
                 wants_smoothed: Callable[[], bool] = lambda: True,
                 watch_config: Optional[WatchConfig] = None) -> None:
        """
        Create the synchroniser; ``start`` adds the fusion once the cameras are known.

        ``watch_config``: the calibration watch's (default: what ``fusion_config`` asks for).
        """
        self.camera_ids = tuple(camera_ids)
        self.layout = get_layout(layout)
        self.sync_config, self.fusion_config = sync_config, fusion_config
        self.sync = StreamSynchronizer(self.camera_ids, sync_config, clock=_no_clock)
        self.fusion: Optional[Fusion] = None
        self.watch = CalibrationWatch.unstarted(watch_config or WatchConfig.of(fusion_config))
        self.log = log or LiveLog()
        #: Whether a fixed-lag estimate is wanted now (the node: ~/tracks_smoothed has a
        #: subscriber); its window is kept regardless.
        self.wants_smoothed = wants_smoothed
        try:
            root = self.layout.root_joints
        except ValueError:
            root = None
        self.output = LiveOutput(fusion_config.publish_coast_s, publish_tentative, lag, root)
        self.counts: Counter = Counter()       # sets, partial_sets, resets, idle_steps, ...
        self.last_tracks: List[Track] = []     # the last step's tracks, DELETED ones left out
        self.last_set_ns: Optional[int] = None         # stamp of the last step (idle too)
        self._last_set_clock_ns: Optional[int] = None  # node clock when the last set came
        self._last_set_anchor_ns = 0                   # stamp of the last real set
        self._set_steps_ns: Deque[int] = deque(maxlen=9)   # recent set stamp steps (coast)
        self._last_input_ns: Optional[int] = None      # steady clock of the last input
        self._slop_noted = False
        self._out: List[Publication] = []
        #: The camera host clocks: offsets from arrival delays, the cameras named off.
        self.clocks = ClockCheck(self.camera_ids, self.sync.stats,
                                 sync_config.offset_warn_fraction,
                                 lambda key, text: self.log.throttled(key, text))

    @property
    def publish_tentative(self) -> bool:
        """Return whether TENTATIVE tracks are published (may change at any time)."""
        return self.output.publisher.publish_tentative

    @publish_tentative.setter
    def publish_tentative(self, value: bool) -> None:
        self.output.publisher.publish_tentative = bool(value)

    def start(self, cameras: Mapping[str, Any]) -> Fusion:
        """Build the fusion for ``cameras`` (calibration known); return it."""
        rig = {c: cameras[c] for c in self.camera_ids}
        self.fusion = Fusion(rig, self.layout, self.fusion_config)
        self.watch = CalibrationWatch(rig, self.watch.config)
        return self.fusion

    @property
    def cameras(self) -> Mapping[str, Any]:
        """Return the rig in use (the calibration watch's corrections included)."""
        return self.watch.cameras

    # ------------------------------------------------------------------ inputs
    def heard(self, now_ns: int) -> None:
        """Note that some input arrived at ``now_ns`` (used or not: the rig is not idle)."""
        self._last_input_ns = now_ns

    def add(self, camera: str, stamp_ns: int, poses: np.ndarray, now_ns: int,
            clock_ns: int) -> Intake:
        """Take one camera's validated poses, arrived at ``now_ns``; process what it lets go."""
        result = self.sync.add(camera, stamp_ns, poses, now_ns)
        intake = Intake(result.accepted, result.kind, result.reason, result.reset)
        if result.accepted or result.kind == 'late':
            self.clocks.observe(camera, stamp_ns, clock_ns)
        if result.reset:
            self._reset(result.reason, from_sync=True)
        if result.kind == 'late':
            if self.fusion_config.view_updates:
                intake.late_used = self._late(camera, poses, stamp_ns)
            else:
                intake.late_refused = True
        if self.sync.slop_note and not self._slop_noted:
            self._slop_noted = True      # e.g. sync.slop_s wider than half the frame period
            self.log.warning(self.sync.slop_note)
        for synced in result.sets:
            self._process(synced, clock_ns)
        self._release(now_ns, clock_ns)     # after a late message too (add decides nothing)
        intake.publications = self._take()
        return intake

    def dropped(self, camera: str, stamp_ns: int, reason: str, now_ns: int,
                clock_ns: int) -> List[Publication]:
        """
        Count the stamp of a message dropped by the node's validation, for ``reason``.

        It was dropped here, not lost upstream, and its stamp may show that the camera sends
        nothing for a pending set. A future stamp beyond ``sync.jump_s`` is not noted.
        """
        seen = self.sync.stats[camera].last_seen_ns
        if stamp_ns > 0 and (reason != 'future_stamp' or seen is None or
                             stamp_ns - seen <= self.sync_config.jump_s * NS_PER_S):
            self.sync.observe(camera, stamp_ns)
            self._release(now_ns, clock_ns)
        return self._take()

    def skip(self, camera: str, after_ns: int, before_ns: int, now_ns: int,
             clock_ns: int) -> List[Publication]:
        """Stop waiting for the camera's images strictly between the two stamps."""
        if self.fusion is not None:
            for synced in self.sync.skip(camera, after_ns, before_ns, now_ns):
                self._process(synced, clock_ns)
        return self._take()

    def release(self, now_ns: int, clock_ns: int) -> List[Publication]:
        """Process the sets whose wait for missing cameras ran out at ``now_ns``."""
        self._release(now_ns, clock_ns)
        return self._take()

    def next_release_ns(self, now_ns: int) -> Optional[int]:
        """Return when (steady clock) ``release`` may next let a set go; None: nothing pends."""
        return self.sync.next_decision_ns(now_ns) if self.fusion is not None else None

    def step_set(self, views: Mapping[str, np.ndarray], stamp_ns: int,
                 stamp: Optional[float] = None, missing: Sequence[str] = (),
                 clock_ns: int = 0) -> List[Publication]:
        """Process one set known to be complete (offline frames), as a synchronised one."""
        self._process(SyncedSet(stamp_ns, dict(views), {c: stamp_ns for c in views},
                                tuple(missing)), clock_ns, stamp)
        return self._take()

    def flush(self) -> List[Publication]:
        """Return the fixed-lag sets still held (end of input), settled with what is known."""
        return [Publication(k, s, t, smoothed=True) for k, s, t in self.output.flush()]

    # ------------------------------------------------------------------ time
    def idle_step(self, now_ns: int, clock_ns: int) -> List[Publication]:
        """
        Age the tracks while no input set arrives: empty steps, as the tracker would get them.

        Once no set came for ``fusion.max_coast_s`` (and longer than the synchroniser could
        wait) and no input at all arrived for as long, each call steps the tracks with no
        views at the last set's stamp advanced by the node-clock time since (less that wait),
        so they go COASTING and are DELETED after ``fusion.max_coast_s`` as with empty sets; a
        message stamped before that time is then late. Under sim time a stalled clock stops
        this too. Called every ``IDLE_STEP_S`` by the node.
        """
        if self.fusion is None or not len(self.fusion.tracker.tracks) or \
                self.last_set_ns is None or self._last_set_clock_ns is None or \
                self.sync.pending():
            return []
        if clock_ns <= 0 or self._last_set_clock_ns <= 0:
            return []      # sim time before the first /clock: no elapsed time to judge
        idle_ns = clock_ns - self._last_set_clock_ns
        # Frames captured up to (now - wait) would have arrived: the empty step stands for
        # them. Stepping only starts after max_coast_s, so a hiccup of a publisher (or a
        # replay slower than real time) does not turn its next frames late.
        wait_ns = self.sync.max_wait_ns + \
            (self.sync.frame_period_ns or int(IDLE_STEP_S * NS_PER_S))
        coast_ns = int(self.fusion.max_coast_s * NS_PER_S)
        if idle_ns <= max(wait_ns, coast_ns):
            return []
        if self._last_input_ns is not None and now_ns - self._last_input_ns <= coast_ns:
            return []      # inputs still arrive (dropped, e.g. under a stalled clock): no gap
        stamp_ns = self._last_set_anchor_ns + idle_ns - wait_ns
        if stamp_ns <= self.last_set_ns or stamp_ns > self.last_set_ns + MAX_IDLE_SPAN_NS:
            return []      # nothing to age, or a node clock that jumped far ahead
        self.sync.decide_through(stamp_ns)
        self.counts['idle_steps'] += 1
        self._step({}, stamp_ns, idle=True)
        return self._take()

    def reset(self, why: str) -> List[Publication]:
        """Clear synchroniser and tracks; return the tombstones of the published tracks."""
        self._reset(why)
        return self._take()

    # ------------------------------------------------------------------ internals
    def _take(self) -> List[Publication]:
        out, self._out = self._out, []
        return out

    def _release(self, now_ns: int, clock_ns: int) -> None:
        if self.fusion is not None and self.sync.pending():
            for synced in self.sync.poll(now_ns):
                self._process(synced, clock_ns)

    def _late(self, camera: str, poses: np.ndarray, stamp_ns: int) -> bool:
        """Fold a message that missed its set into the tracks at its own stamp."""
        if camera in self.watch.excluded():
            return False
        try:
            used = self.fusion.update_view(camera, poses, stamp_ns / NS_PER_S, stamp_ns)
        except Exception as exc:  # noqa: B902 - a core failure must not stop the node
            self.counts['fusion_errors'] += 1
            self.log.throttled('fusion_error', f'Fusion.update_view failed on camera {camera} '
                               f'at {stamp_ns / NS_PER_S:.6f} s ({exc!r}); message dropped')
            return False
        # 0: every joint it saw was updated after its stamp (or nobody to update): it brought
        # nothing, and counts as late in /diagnostics, not as rejected
        return bool(used)

    def _reset(self, why: str, from_sync: bool = False) -> None:
        self.counts['resets'] += 1
        self.clocks.reset()
        self.log.warning(f'reset: {why}; synchroniser and tracks cleared')
        if not from_sync:
            self.sync.reset()
        tombs = self.fusion.reset() if self.fusion is not None else []
        tombs, held = self.output.reset(tombs)
        self._out += [Publication(k, s, t, smoothed=True) for k, s, t in held]
        self.last_tracks = []
        if tombs and self.last_set_ns is not None:
            self._out.append(Publication(self.last_set_ns, self.last_set_ns / NS_PER_S, tombs))
            self._out.append(Publication(self.last_set_ns, 0.0, tombs, smoothed=True))
        self.last_set_ns = None
        self._last_set_clock_ns = None

    def _process(self, synced: SyncedSet, clock_ns: int, stamp: Optional[float] = None) -> None:
        self._last_set_clock_ns = clock_ns
        self._adapt_coast(synced.stamp_ns)
        self._last_set_anchor_ns = synced.stamp_ns
        if self._step(synced.messages, synced.stamp_ns, stamp):
            self.counts['sets'] += 1
            if synced.missing:
                self.counts['partial_sets'] += 1

    def _adapt_coast(self, stamp_ns: int) -> None:
        """Let tracks coast COAST_SET_PERIODS set periods at least (slow sets keep tracks)."""
        step = stamp_ns - self._last_set_anchor_ns
        if self._last_set_anchor_ns and 0 < step < 30 * NS_PER_S:
            self._set_steps_ns.append(step)
        if len(self._set_steps_ns) < 3:
            return
        period = sorted(self._set_steps_ns)[len(self._set_steps_ns) // 2] / NS_PER_S
        coast = max(self.fusion_config.max_coast_s, COAST_SET_PERIODS * period)
        now = self.fusion.max_coast_s
        if abs(coast - now) > 0.05 * now:
            self.log.info(f'tracks coast {coast:.2f} s (sets every {period:.2f} s; '
                          f'fusion.max_coast_s {self.fusion_config.max_coast_s:g} s)')
            self.fusion.max_coast_s = coast

    def _step(self, views: Mapping[str, Any], stamp_ns: int, stamp: Optional[float] = None,
              idle: bool = False) -> bool:
        """Run ``Fusion.step`` and queue its publications; False when the core failed."""
        stamp = stamp_ns / NS_PER_S if stamp is None else stamp
        t0 = time.perf_counter()     # a measurement for /diagnostics, not a policy input
        try:
            tracks, events = self.watch.fused(self.fusion, views, stamp, stamp_ns)
        except Exception as exc:  # noqa: B902 - a core failure must not stop the node
            self.counts['fusion_errors'] += 1
            self.log.throttled('fusion_error', f'Fusion.step failed on the set at '
                               f'{stamp_ns / NS_PER_S:.6f} s ({exc!r}); tracks reset')
            self.fusion.reset()
            self._out += [Publication(k, s, t, smoothed=True)
                          for k, s, t in self.output.reset()[1]]
            return False
        processing = None if idle else time.perf_counter() - t0
        for event in events:
            self._watched(event)
        self.last_tracks = [t for t in tracks if t.state != TrackState.DELETED]
        out, smoothed = self.output.step(tracks, stamp, stamp_ns, smoothed=self.wants_smoothed())
        self._out.append(Publication(stamp_ns, stamp, out, latency=not idle,
                                     processing_s=processing))
        if smoothed is not None:
            self._out.append(Publication(*smoothed, smoothed=True))
        self.last_set_ns = stamp_ns
        return True

    def _watched(self, event: WatchEvent) -> None:
        """Say what the calibration watch found (its correction is in the fusion already)."""
        self.counts[f'watch_{event.kind}'] += 1
        if event.kind == 'error':
            self.log.throttled('watch_error', event.message)
        elif event.kind == 'agrees':
            self.log.info(event.message)
        else:
            self.log.warning(event.message)
        if event.kind == 'corrected':
            self.log.rig(dict(self.watch.cameras))


def _no_clock() -> int:
    """Stand in for the synchroniser's clock: ``LiveFusion`` always passes the time."""
    raise RuntimeError('LiveFusion passes the arrival time to the synchroniser')
