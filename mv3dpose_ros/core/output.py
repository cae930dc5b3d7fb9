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

import dataclasses
from typing import Dict, Iterable, List, Optional, Tuple

from mv3dpose_ros.core.smoothing import FixedLagSmoother
from mv3dpose_ros.core.types import Track, TrackState


class TrackPublisher:
    """Filter ``Fusion.step`` outputs for publication and map them to public ids."""

    def __init__(self, publish_tentative: bool = False, publish_coast_s: float = 0.1) -> None:
        """Create the publisher (``publish_tentative`` may be changed at any time)."""
        if not publish_coast_s >= 0:
            raise ValueError(f'TrackPublisher: publish_coast_s must be >= 0, got '
                             f'{publish_coast_s}')
        self.publish_tentative = bool(publish_tentative)
        self.publish_coast_s = float(publish_coast_s)
        self._public: Dict[int, int] = {}      # internal id -> public id, while published
        self.next_id = 1

    @property
    def published_ids(self) -> List[int]:
        """Return the public ids of the tracks published and not yet deleted."""
        return sorted(self._public.values())

    def publish(self, tracks: Iterable[Track], stamp: float) -> List[Track]:
        """Return the tracks of one ``Fusion.step`` (at ``stamp`` s) that are published."""
        out = []
        for t in tracks:
            if t.state == TrackState.DELETED:
                public = self._public.pop(t.track_id, None)
                if public is not None:
                    out.append(dataclasses.replace(t, track_id=public))
                continue
            if t.state == TrackState.TENTATIVE and not self.publish_tentative:
                continue
            if t.state == TrackState.COASTING \
                    and stamp - t.last_observed > self.publish_coast_s + 1e-9:
                continue
            public = self._public.get(t.track_id)
            if public is None:
                public = self._public[t.track_id] = self.next_id
                self.next_id += 1
            out.append(dataclasses.replace(t, track_id=public))
        out.sort(key=lambda t: (t.state == TrackState.DELETED, t.track_id))
        return out

    def reset(self, tombstones: Iterable[Track] = ()) -> List[Track]:
        """Forget all tracks; return the published ones among ``tombstones`` (public ids)."""
        out = [dataclasses.replace(t, track_id=self._public[t.track_id])
               for t in tombstones if t.track_id in self._public]
        self._public.clear()
        return out


class LiveOutput:
    """
    The live outputs of one ``Fusion``: ``~/tracks`` and, with ``lag > 0``, the fixed-lag one.

    ``step`` takes one ``Fusion.step`` result and returns the published tracks and, once the
    window is full, the smoothed set ``lag`` steps back (``FixedLagSmoother``), as
    ``(key, stamp, tracks)`` with the key (frame number, or stamp in ns) it was given then.
    ``fusion_node`` and ``mv3dpose track`` both run exactly this.
    """

    def __init__(self, publish_coast_s: float = 0.1, publish_tentative: bool = False,
                 lag: int = 0, root_joints: Optional[Tuple[int, int]] = None) -> None:
        """Create the publisher and, for ``lag > 0``, the fixed-lag smoother."""
        self.publisher = TrackPublisher(publish_tentative, publish_coast_s)
        self.smoother = FixedLagSmoother(lag, root_joints=root_joints) if lag > 0 else None

    def step(self, tracks: Iterable[Track], stamp: float, key: object = None
             ) -> Tuple[List[Track], Optional[Tuple[object, float, List[Track]]]]:
        """Return ``(published tracks, smoothed set or None)`` for one set at ``stamp`` s."""
        published = self.publisher.publish(tracks, stamp)
        if self.smoother is None:
            return published, None
        return published, self.smoother.push(key, stamp, published)

    def flush(self) -> List[Tuple[object, float, List[Track]]]:
        """Return the smoothed sets still held (end of input)."""
        return self.smoother.flush() if self.smoother is not None else []

    def reset(self, tombstones: Iterable[Track] = ()
              ) -> Tuple[List[Track], List[Tuple[object, float, List[Track]]]]:
        """Forget all tracks: the published tombstones (public ids) and the held sets."""
        return self.publisher.reset(tombstones), self.flush()
