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
What a live consumer sees of ``Fusion.step``: the publication rules and public track ids.

``Fusion.step`` reports every track it keeps (internal ids). ``TrackPublisher`` turns that
into the published stream, shared by ``fusion_node`` (``~/tracks``) and ``mv3dpose track
--smooth causal`` (``LiveOutput`` adds the fixed-lag stream, ``~/tracks_smoothed`` and
``--smooth fixed-lag``):

- CONFIRMED tracks are published; TENTATIVE ones only with ``publish_tentative``;
- a COASTING track is published for at most ``publish_coast_s`` after its last observation,
  then withheld (no stale prediction is presented) until it is observed again or deleted;
- a DELETED tombstone is published once, for tracks that were published;
- public ids are allocated when a track is first published, from 1 up, so they have no gaps,
  and are never reused (not after ``reset`` either).
"""

from collections import deque
import dataclasses
from typing import Deque, Dict, Iterable, List, Optional, Set, Tuple

from mv3dpose_ros.core.tracking.smoothing import FixedLagSmoother
from mv3dpose_ros.core.types import Track, TrackState
import numpy as np


class TrackPublisher:
    """Filter ``Fusion.step`` outputs for publication and map them to public ids."""

    def __init__(self, publish_tentative: bool = False, publish_coast_s: float = 0.15) -> None:
        """Create the publisher (``publish_tentative`` may be changed at any time)."""
        if not publish_coast_s >= 0:
            raise ValueError(f'TrackPublisher: publish_coast_s must be >= 0, got '
                             f'{publish_coast_s}')
        self.publish_tentative = bool(publish_tentative)
        self.publish_coast_s = float(publish_coast_s)
        self._public: Dict[int, int] = {}      # internal id -> public id, while published
        self._ever: Dict[int, int] = {}        # internal id -> public id, since allocated
        self.retain = False                     # keep _ever after a tombstone (see forget)
        self.last_published: Set[int] = set()  # internal ids published by the last call
        self.next_id = 1

    @property
    def published_ids(self) -> List[int]:
        """Return the public ids of the tracks published and not yet deleted."""
        return sorted(self._public.values())

    def public_id(self, internal: int) -> Optional[int]:
        """Return the public id given to internal track ``internal`` (None: never published)."""
        return self._ever.get(internal)

    def publish(self, tracks: Iterable[Track], stamp: float) -> List[Track]:
        """Return the tracks of one ``Fusion.step`` (at ``stamp`` s) that are published."""
        out = []
        self.last_published = set()
        for t in tracks:
            if t.state == TrackState.DELETED:
                public = self._public.pop(t.track_id, None)
                if public is not None:
                    out.append(dataclasses.replace(t, track_id=public))
                    self.last_published.add(t.track_id)
                    if not self.retain:
                        self._ever.pop(t.track_id, None)
                continue
            if t.state == TrackState.TENTATIVE and not self.publish_tentative:
                continue
            if t.state == TrackState.COASTING \
                    and stamp - t.last_observed > self.publish_coast_s + 1e-9:
                continue
            public = self._public.get(t.track_id)
            if public is None:
                public = self._public[t.track_id] = self._ever[t.track_id] = self.next_id
                self.next_id += 1
            out.append(dataclasses.replace(t, track_id=public))
            self.last_published.add(t.track_id)
        out.sort(key=lambda t: (t.state == TrackState.DELETED, t.track_id))
        return out

    def forget(self, internal: int) -> None:
        """Drop the id of a deleted track kept for a consumer that lags (``retain``)."""
        self._ever.pop(internal, None)

    def reset(self, tombstones: Iterable[Track] = ()) -> List[Track]:
        """Forget all tracks; return the published ones among ``tombstones`` (public ids)."""
        out = [dataclasses.replace(t, track_id=self._public[t.track_id])
               for t in tombstones if t.track_id in self._public]
        self._public.clear()
        self._ever.clear()
        return out


class LiveOutput:
    """
    The live outputs of one ``Fusion``: ``~/tracks`` and, with ``lag > 0``, the fixed-lag one.

    ``step`` takes one ``Fusion.step`` result and returns the published tracks and, once the
    window is full, the set ``lag`` steps back re-estimated with what came after it
    (``FixedLagSmoother``), as ``(key, stamp, tracks)`` with the key (frame number, or stamp
    in ns) it was given then. ``fusion_node`` and ``mv3dpose track`` both run exactly this.

    The fixed-lag set holds the tracks published for it, plus what the lag settles: a COASTING
    track withheld by ``publish_coast_s`` whose person is observed again within the lag (the
    gap is bridged, its joints interpolated), and a TENTATIVE track that is confirmed within
    the lag (reported CONFIRMED, with the public id it got then). Ids are the public ids.
    """

    def __init__(self, publish_coast_s: float = 0.15, publish_tentative: bool = False,
                 lag: int = 0, root_joints: Optional[Tuple[int, int]] = None) -> None:
        """Create the publisher and, for ``lag > 0``, the fixed-lag smoother."""
        self.publisher = TrackPublisher(publish_tentative, publish_coast_s)
        self.lag = int(lag)
        self.smoother = FixedLagSmoother(lag, root_joints=root_joints) if lag > 0 else None
        self.publisher.retain = self.smoother is not None
        # per set still held by the smoother: (internal ids published, internal ids observed)
        self._held: Deque[Tuple[Set[int], Set[int]]] = deque()

    def step(self, tracks: Iterable[Track], stamp: float, key: object = None,
             smoothed: bool = True
             ) -> Tuple[List[Track], Optional[Tuple[object, float, List[Track]]]]:
        """
        Return ``(published tracks, fixed-lag set or None)`` for one set at ``stamp`` s.

        ``smoothed=False`` (nobody consumes the fixed-lag stream now) skips its estimation and
        returns None for it; the sets are kept all the same, so the fixed-lag sets returned
        once ``smoothed`` is True again are exactly those of an uninterrupted stream.
        """
        tracks = list(tracks)
        published = self.publisher.publish(tracks, stamp)
        if self.smoother is None:
            return published, None
        self._held.append((self.publisher.last_published,
                           {t.track_id for t in tracks if _observed(t)}))
        done = self.smoother.push(key, stamp, tracks, smooth=smoothed)
        if done is None:
            return published, None
        settled = self._settle(done, build=smoothed)
        return published, settled if smoothed else None

    def flush(self) -> List[Tuple[object, float, List[Track]]]:
        """Return the fixed-lag sets still held (end of input), settled with what is known."""
        if self.smoother is None:
            return []
        return [self._settle(done) for done in self.smoother.flush()]

    def reset(self, tombstones: Iterable[Track] = ()
              ) -> Tuple[List[Track], List[Tuple[object, float, List[Track]]]]:
        """Forget all tracks: the published tombstones (public ids) and the held sets."""
        held = self.flush()
        return self.publisher.reset(tombstones), held

    def _settle(self, done: Tuple[object, float, List[Track]], build: bool = True
                ) -> Tuple[object, float, List[Track]]:
        """Pick and rename the tracks of the oldest held set (see the class docstring)."""
        key, stamp, tracks = done
        published, _ = self._held.popleft()
        if not build:       # the bookkeeping only: ids of deleted tracks are let go
            for t in tracks:
                if t.state == TrackState.DELETED:
                    self.publisher.forget(t.track_id)
            return key, stamp, []
        later: Set[int] = set()
        for _, observed in list(self._held)[:self.lag]:
            later |= observed
        out = []
        for t in tracks:
            public = self.publisher.public_id(t.track_id)
            if public is None:
                continue
            if t.state == TrackState.DELETED:
                self.publisher.forget(t.track_id)
            if t.track_id in published:
                out.append(dataclasses.replace(t, track_id=public))
            elif t.state == TrackState.COASTING and t.track_id in later:
                out.append(dataclasses.replace(t, track_id=public))
            elif t.state == TrackState.TENTATIVE:
                out.append(dataclasses.replace(t, track_id=public, state=TrackState.CONFIRMED))
        out.sort(key=lambda t: (t.state == TrackState.DELETED, t.track_id))
        return key, stamp, out


def _observed(track: Track) -> bool:
    """Tell whether the joint filters accepted an observation of ``track`` in its set."""
    return track.state != TrackState.DELETED and track.measurement is not None \
        and bool(np.isfinite(track.measurement[:, 0]).any())
