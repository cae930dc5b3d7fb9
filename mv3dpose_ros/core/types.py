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
Data types shared by the fusion core, the ROS adapters and the offline tools.

Conventions: 2D poses are ``[P, J, 3]`` arrays of (x px, y px, confidence) in raw (distorted)
image pixels; 3D joints are metres in the world frame (z up) with NaN where a joint is missing.
NaN never leaves the core: the ROS and file adapters turn it into explicit validity fields.
"""

from dataclasses import dataclass, field
import enum
from typing import NamedTuple, Optional, Tuple, Union

import numpy as np

# Nanoseconds per second: stamps are int64 nanoseconds everywhere (ROS time, bags, the core).
NS_PER_S = 1_000_000_000
#: What the calibration watch (core.selfcal.watch) does with a camera that turned.
CALIBRATION_WATCH_MODES = ('off', 'warn', 'exclude', 'correct')


class Stamp(NamedTuple):
    """
    One instant: integer nanoseconds (what ROS, bags and the tracks' ``*_ns`` fields hold).

    ``s`` is the same instant in seconds for arithmetic. Build stamps with ``Stamp.of``, the
    one place where either form is derived from the other: a caller's own seconds are kept as
    given (a frame index over a frame rate is exact in seconds, not in nanoseconds), so the
    arithmetic on them does not move. (A named tuple: immutable, and made in a fraction of a
    dataclass's time, once or twice per set.)
    """

    ns: int
    s: float

    @classmethod
    def of(cls, seconds: 'Union[float, Stamp, None]' = None,
           ns: Optional[int] = None) -> 'Stamp':
        """Return the stamp of ``seconds`` and / or ``ns`` (the missing one derived)."""
        if isinstance(seconds, Stamp):
            return seconds if ns is None or int(ns) == seconds.ns else cls(int(ns), seconds.s)
        if seconds is None:
            if ns is None:
                raise ValueError('Stamp.of needs seconds or nanoseconds')
            return cls(int(ns), int(ns) / NS_PER_S)
        seconds = float(seconds)
        return cls(int(round(seconds * 1e9)) if ns is None else int(ns), seconds)


class TrackState(enum.IntEnum):
    """Track life cycle; values equal the constants of mv3dpose_msgs/TrackedSkeleton."""

    TENTATIVE = 0
    CONFIRMED = 1
    COASTING = 2
    DELETED = 3


class JointState(enum.IntEnum):
    """Per-joint validity; values equal the constants of mv3dpose_msgs/Joint3D."""

    MISSING = 0
    TRIANGULATED = 1
    PREDICTED = 2


class PositionSource(enum.IntEnum):
    """What a track's ``position`` is; values equal mv3dpose_msgs/TrackedSkeleton's."""

    HIPS = 0        # the midpoint of the filtered hip joints (REP-155 body origin)
    BODY = 1        # a hip is unknown: the centre of the track's known joints (covariance
    #                 widened by the hips' usual offset from it)
    NONE = 2        # nothing known (never for a published CONFIRMED or COASTING track)


@dataclass
class Track:
    """One tracked person as output by ``Fusion.step`` for one synchronised set of views."""

    track_id: int
    state: TrackState
    joints: np.ndarray                 # [J, 3] metres, NaN where joint_state == MISSING
    confidence: np.ndarray             # [J] in [0, 1]
    joint_state: np.ndarray            # [J] uint8, JointState values
    num_views: np.ndarray              # [J] uint8, cameras that contributed this cycle
    reprojection_error: np.ndarray     # [J] px, NaN when not triangulated this cycle
    position: np.ndarray               # [3] root (hip midpoint) metres, NaN if unknown
    velocity: np.ndarray               # [3] root velocity m/s, NaN if unknown
    first_seen: float                  # stamp [s] of the set that created the track
    last_observed: float               # stamp [s] of the last set that updated it
    age: int = 0                       # updates with observations
    missed: int = 0                    # consecutive sets without association
    score: float = 0.0                 # track confidence [0, 1]
    source_cameras: Tuple[str, ...] = field(default_factory=tuple)
    # Uncertainty (None when the producer has none, e.g. tracks read back from a file):
    joint_variance: Optional[np.ndarray] = None        # [J] per-axis variance [m^2] of each
    #                                                    joint, NaN where MISSING
    position_covariance: Optional[np.ndarray] = None   # [3, 3] of the root [m^2], NaN if unknown
    # What the joint filters accepted this cycle (for the fixed-lag smoother; not published):
    measurement: Optional[np.ndarray] = None           # [J, 3] metres, NaN where none
    measurement_variance: Optional[np.ndarray] = None  # [J] per-axis [m^2], NaN where none
    # The stamps in exact integer nanoseconds (None: derive from the float seconds):
    first_seen_ns: Optional[int] = None
    last_observed_ns: Optional[int] = None
    position_source: PositionSource = PositionSource.HIPS

    @property
    def num_joints(self) -> int:
        """Return the number of joints of the layout."""
        return int(self.joints.shape[0])

    @property
    def valid(self) -> np.ndarray:
        """Return the boolean mask ``[J]`` of joints with a usable position."""
        return self.joint_state != JointState.MISSING
