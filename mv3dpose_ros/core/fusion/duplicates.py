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
One person, one track: fragments start no track, and two tracks of one person merge.

A candidate within ``merge_distance_m`` of a track (median joint distance) is a fragment of a
tracked person whose views the association split from the rest: no one new (``near_a_track``).
Two published tracks that look like one person for ``DUPLICATE_FRAMES`` steps in a row (close,
and no camera seeing both: one person tracked twice from disjoint views; two people side by
side are seen by the same cameras) are merged into the older id (``DuplicateTracks``).
"""

from collections import Counter
from typing import Dict, Optional, Tuple

from mv3dpose_ros.core.fusion.config import FusionConfig
from mv3dpose_ros.core.fusion.reconstruction import CENTRE_MARGIN_M, upper_triangle
from mv3dpose_ros.core.fusion.record import SetRecord
from mv3dpose_ros.core.tracking.tracker import centroid, median_joint_distance, Tracker, Tracks
from mv3dpose_ros.core.types import TrackState
import numpy as np

#: Steps two tracks must look like one person (close, no shared camera) before they merge.
DUPLICATE_FRAMES = 3

_TENTATIVE_TRACK = np.int8(TrackState.TENTATIVE)


def near_a_track(poses: np.ndarray, predicted: np.ndarray, merge_distance_m: float,
                 min_shared_joints: int) -> np.ndarray:
    """Tell which 3D poses ``[N, J, 3]`` lie within ``merge_distance_m`` of a ``predicted``."""
    a, b = centroid(poses), centroid(predicted)   # cheap first: centres far apart
    d = a[:, None] - b[None]
    with np.errstate(invalid='ignore'):
        maybe = ((d * d).sum(axis=-1)
                 < (merge_distance_m + CENTRE_MARGIN_M) ** 2).any(axis=1)
    out = np.zeros(len(poses), dtype=bool)
    if maybe.any():
        near = median_joint_distance(poses[maybe], predicted, min_shared_joints)
        out[maybe] = (near < merge_distance_m).any(axis=1)
    return out


class DuplicateTracks:
    """Count, per pair of published tracks, the steps they look alike; merge the lasting ones."""

    def __init__(self, config: FusionConfig, tracker: Tracker, counts: Counter) -> None:
        """Watch ``tracker``'s tracks; count 'merged_tracks'."""
        self.config, self.tracker, self._counts = config, tracker, counts
        self._alike: Dict[Tuple[int, int], int] = {}        # id pair -> steps alike

    def clear(self) -> None:
        """Forget every count (the tracks were reset)."""
        self._alike.clear()

    def count(self, s: SetRecord) -> None:
        """
        Count, per pair of published tracks, the consecutive steps they look like one person.

        Alike: median joint distance below ``merge_distance_m`` and no camera seeing both in
        set ``s``. ``merge`` acts on the count before the next step's tracking.
        """
        cfg, tr = self.config, self.tracker.tracks
        live = np.nonzero(tr.state != _TENTATIVE_TRACK)[0]
        if len(live) < 2 or cfg.merge_distance_m <= 0:
            self._alike.clear()
            return
        # pairs no camera saw both of now (two people side by side share cameras): the
        # common case of a complete set has none (a camera saw them all)
        seen = s.track_cameras[live]
        if seen.all(axis=0).any():
            self._alike.clear()
            return
        c = seen.astype(np.float64)
        apart = (c @ c.T == 0) & upper_triangle(len(live))
        if not apart.any():
            self._alike.clear()
            return
        # the centres next (cheap): mean joint distances below the merge distance need
        # centres within about as much
        centre = centroid(tr.pose[live])
        d = centre[:, None] - centre[None]
        with np.errstate(invalid='ignore'):
            apart &= (d * d).sum(axis=-1) < (cfg.merge_distance_m + CENTRE_MARGIN_M) ** 2
        if not apart.any():
            self._alike.clear()
            return
        dist = median_joint_distance(tr.pose[live], tr.pose[live], cfg.min_shared_joints)
        close = (dist < cfg.merge_distance_m) & apart
        ids = tr.ids.tolist()
        alike = {}
        for i, j in zip(*np.nonzero(close)):
            key = (ids[live[i]], ids[live[j]])
            alike[key] = self._alike.get(key, 0) + 1
        self._alike = alike

    def merge(self) -> Optional[Tracks]:
        """Delete the younger of each pair alike for ``DUPLICATE_FRAMES`` steps (or None)."""
        if not self._alike:
            return None
        tr = self.tracker.tracks
        row = {tid: r for r, tid in enumerate(tr.ids.tolist())}
        drop = set()
        for (a, b), frames in sorted(self._alike.items()):
            if frames >= DUPLICATE_FRAMES and a in row and b in row \
                    and a not in drop and b not in drop:
                older = a if (tr.first_seen[row[a]], a) <= (tr.first_seen[row[b]], b) else b
                drop.add(b if older == a else a)
        self._alike = {k: n for k, n in self._alike.items() if not set(k) & drop}
        if not drop:
            return None
        self._counts['merged_tracks'] += len(drop)
        return self.tracker.remove(np.array(sorted(row[d] for d in drop)))
