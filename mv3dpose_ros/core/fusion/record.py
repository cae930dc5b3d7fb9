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
What one step knows about its set, in one record the stages fill in turn.

``Fusion.step`` makes a ``SetRecord`` from the reconstruction (``Points``, the candidates'
``Triangulation`` and ``members``), the tracker adds its ``TrackUpdate`` and the tracks'
members, the single views their ``Rays``; the output and the duplicate count read it.
"""

from dataclasses import dataclass, field
from typing import Dict, Optional, Tuple

from mv3dpose_ros.core.geometry.triangulation import Triangulation
from mv3dpose_ros.core.tracking.tracker import TrackUpdate
from mv3dpose_ros.core.types import Stamp
import numpy as np


@dataclass
class Points:
    """The usable 2D poses of one set, normalised and stacked camera by camera (rig order)."""

    x: np.ndarray                   # [N + 1, J, 3] homogeneous normalised points, NaN: missing;
    #                                 row N is a missing pose: index -1 of a members table
    #                                 picks it, so camera-major gathers need no masking
    conf: np.ndarray                # [N + 1, J] detector confidence (0: missing)
    offsets: Tuple[int, ...]        # C + 1 ints: camera c has rows offsets[c]:offsets[c + 1]
    camera: np.ndarray              # [N] rig index of each pose's camera
    source: np.ndarray              # [N] index of each pose in its view

    @property
    def count(self) -> int:
        """Return N, the number of poses."""
        return self.offsets[-1]


@dataclass
class Rays:
    """Single-view updates of one step, per live track (see ``ViewUpdates.update_set``)."""

    accepted: np.ndarray    # [T, J] a view updated the joint
    point: np.ndarray       # [T, J, 3] the first accepted ray's point nearest the prediction
    variance: np.ndarray    # [T, J] its variance across the ray [m^2]
    views: np.ndarray       # [T, J] views that updated the joint
    cameras: np.ndarray     # [T, C] cameras whose pose went to the track (member or single)


@dataclass
class SetRecord:
    """One synchronised set on its way through ``Fusion.step``."""

    stamp: Stamp
    present: np.ndarray             # [C] bool, cameras with a view in the set
    sparse: bool                    # a camera of the rig has no view in the set
    points: Points
    tri: Triangulation              # the K candidate 3D poses
    members: np.ndarray             # [K, C] row of ``points.x`` behind each candidate, -1: none
    info: Dict[str, int] = field(default_factory=dict)    # counts for ``Fusion.last_info``
    centres: Optional[np.ndarray] = None        # [K, 3] the candidates' joint centroids, when
    #                                             the reconstruction computed them
    variance: Optional[np.ndarray] = None       # [K, J] per-axis measurement variance [m^2]
    update: Optional[TrackUpdate] = None        # what the tracker did, [T] live tracks
    track_members: Optional[np.ndarray] = None  # [T, C] ``members`` of each live track's 3D
    #                                             pose of this set (-1: none or no pose)
    track_seen: Optional[np.ndarray] = None     # [T, C] ``track_members >= 0``
    rays: Optional[Rays] = None                 # single-view updates (None: none)

    @property
    def track_cameras(self) -> np.ndarray:
        """Return ``[T, C]``: the cameras whose poses went to each live track in this set."""
        return self.rays.cameras if self.rays is not None else self.track_seen
