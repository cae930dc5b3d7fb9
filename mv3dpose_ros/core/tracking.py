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
Frame-to-frame tracking of 3D poses (paper, step 3) with a track life cycle.

Each set of 3D poses is matched to the live tracks by a gated Hungarian solve. The cost of a
(track, pose) pair is the mean Euclidean distance over the joints both have (at least
``min_shared_joints``); with fewer shared joints it is the distance of their joint centroids
on the ground plane (x, y; world z is up). A pair is accepted below the gate
``gate_m + gate_growth_mps * (time since the track was last observed)``: the paper's
tau = 0.2 m between consecutive frames, widened for tracks that were not seen for a while and
for low frame rates. With ``predict`` each track is first moved by its root velocity (constant
velocity), so walking people stay inside the gate at low frame rates.

Life cycle: a new track is TENTATIVE; after ``confirm_hits`` observations it is CONFIRMED; a
confirmed track that misses a set is COASTING until it is observed again (CONFIRMED) or
``max_coast_s`` pass without observation (DELETED). A TENTATIVE track that misses a set is
DELETED at once. Ids start at 1 and are never reused by a tracker.
"""

from dataclasses import dataclass, field
from typing import List, Optional, Tuple

from mv3dpose_ros.core.types import TrackState
import numpy as np
from scipy.optimize import linear_sum_assignment


@dataclass
class TrackerConfig:
    """Tracking parameters (units in the names)."""

    gate_m: float = 0.2
    gate_growth_mps: float = 1.0
    min_shared_joints: int = 3
    predict: bool = True
    confirm_hits: int = 3
    max_coast_s: float = 1.0
    min_birth_joints: int = 6
    velocity_smoothing: float = 0.5


@dataclass
class TrackRecord:
    """Internal state of one track (the tracker's view, before output smoothing)."""

    track_id: int
    state: TrackState
    pose: np.ndarray              # [J, 3] last observed joints, older values where missing
    first_seen: float
    last_observed: float
    last_stamp: float             # stamp of the last update (observed or not)
    hits: int = 1
    missed: int = 0
    velocity: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))  # root m/s
    fresh: Optional[np.ndarray] = None   # [J] joints refreshed by the last observation
    detection: int = -1           # index of the pose matched in this update, -1 = none
    extra: Optional[object] = None   # per-track data of the caller (e.g. its smoother)

    def predicted(self, stamp: float, predict: bool = True) -> np.ndarray:
        """Return the pose moved by the root velocity to ``stamp`` (no-op without velocity)."""
        if not predict or not np.isfinite(self.velocity).all():
            return self.pose
        return self.pose + self.velocity * (stamp - self.last_observed)


def centroid(poses: np.ndarray) -> np.ndarray:
    """Return the ``[..., 3]`` mean of the finite joints of ``[..., J, 3]`` poses (NaN if none)."""
    ok = np.isfinite(poses).all(axis=-1)
    n = ok.sum(axis=-1)
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(ok[..., None], poses, 0.0).sum(axis=-2) / np.where(n > 0, n, np.nan)[
            ..., None]


def pose_distance(a: np.ndarray, b: np.ndarray, min_shared_joints: int = 3) -> np.ndarray:
    """
    Return the ``[A, B]`` tracking cost between poses ``a [A, J, 3]`` and ``b [B, J, 3]``.

    Mean joint distance over shared finite joints, or ground-plane centroid distance when fewer
    than ``min_shared_joints`` are shared (inf if either pose is empty).
    """
    diff = np.linalg.norm(a[:, None] - b[None], axis=-1)            # [A, B, J], NaN if missing
    ok = np.isfinite(diff)
    n = ok.sum(axis=-1)
    mean = np.where(ok, diff, 0.0).sum(axis=-1) / np.maximum(n, 1)
    ca, cb = centroid(a)[:, :2], centroid(b)[:, :2]
    ground = np.linalg.norm(ca[:, None] - cb[None], axis=-1)
    cost = np.where(n >= min_shared_joints, mean, ground)
    return np.where(np.isfinite(cost), cost, np.inf)


class Tracker:
    """Assign 3D poses to tracks over time and run their life cycle."""

    def __init__(self, config: Optional[TrackerConfig] = None, root_joints=None) -> None:
        """Create an empty tracker; ``root_joints`` (indices) define the root, else centroid."""
        self.config = config or TrackerConfig()
        self.root_joints = None if root_joints is None else np.asarray(root_joints, dtype=int)
        self.tracks: List[TrackRecord] = []
        self.next_id = 1

    def reset(self) -> List[TrackRecord]:
        """Drop all tracks (ids keep counting up) and return them marked DELETED."""
        dropped = self.tracks
        for t in dropped:
            t.state = TrackState.DELETED
            t.detection = -1
        self.tracks = []
        return dropped

    def root(self, pose: np.ndarray) -> np.ndarray:
        """Return the root of a ``[J, 3]`` pose: mean of the root joints, else the centroid."""
        if self.root_joints is not None:
            r = pose[self.root_joints]
            if np.isfinite(r).all():
                return r.mean(axis=0)
        return centroid(pose)

    def update(self, poses: np.ndarray, stamp: float, can_birth: Optional[np.ndarray] = None
               ) -> Tuple[List[TrackRecord], List[TrackRecord]]:
        """
        Match ``poses [D, J, 3]`` (NaN = missing joint) observed at ``stamp`` seconds.

        Returns ``(live, deleted)``: the live tracks after the update (``detection`` = index of
        their pose, -1 if not observed this time, new tracks included) and the tracks deleted
        in this update (state DELETED, each reported once). Unmatched poses start tracks only
        where ``can_birth [D]`` (default: all) holds and they have ``min_birth_joints``.
        """
        cfg = self.config
        num_det = len(poses)
        det_idx = np.full(len(self.tracks), -1)
        if self.tracks and num_det:
            pred = np.stack([t.predicted(stamp, cfg.predict) for t in self.tracks])
            cost = pose_distance(pred, poses, cfg.min_shared_joints)
            since = np.array([stamp - t.last_observed for t in self.tracks])
            gate = cfg.gate_m + cfg.gate_growth_mps * np.maximum(since, 0.0)
            feasible = cost < gate[:, None]
            if feasible.any():
                rows, cols = linear_sum_assignment(np.where(feasible, cost, 1e6))
                keep = feasible[rows, cols]
                det_idx[rows[keep]] = cols[keep]
        used = np.zeros(num_det, dtype=bool)
        live, deleted = [], []
        for t, d in zip(self.tracks, det_idx):
            t.detection = int(d)
            if d >= 0:
                used[d] = True
                self._observe(t, poses[d], stamp)
                live.append(t)
                continue
            t.missed += 1
            t.last_stamp = stamp
            if t.state == TrackState.TENTATIVE or stamp - t.last_observed > cfg.max_coast_s:
                t.state = TrackState.DELETED
                deleted.append(t)
            else:
                t.state = TrackState.COASTING
                live.append(t)
        for d in np.nonzero(~used)[0]:
            pose = poses[d]
            if np.isfinite(pose).all(axis=-1).sum() < cfg.min_birth_joints or (
                    can_birth is not None and not can_birth[d]):
                continue
            t = TrackRecord(track_id=self.next_id, state=TrackState.TENTATIVE,
                            pose=pose.copy(), first_seen=stamp, last_observed=stamp,
                            last_stamp=stamp, detection=int(d),
                            fresh=np.isfinite(pose).all(axis=-1))
            if cfg.confirm_hits <= 1:
                t.state = TrackState.CONFIRMED
            self.next_id += 1
            live.append(t)
        self.tracks = live
        return live, deleted

    def _observe(self, t: TrackRecord, pose: np.ndarray, stamp: float) -> None:
        dt = stamp - t.last_observed
        ok = np.isfinite(pose).all(axis=-1)
        both = ok & t.fresh if t.fresh is not None else ok & np.isfinite(t.pose).all(axis=-1)
        if dt > 0 and both.sum() >= self.config.min_shared_joints:
            v = (pose[both] - t.pose[both]).mean(axis=0) / dt
            a = self.config.velocity_smoothing
            t.velocity = v if not np.isfinite(t.velocity).all() else a * t.velocity + (1 - a) * v
        t.pose = np.where(ok[:, None], pose, t.pose)
        t.fresh = ok
        t.hits += 1
        t.missed = 0
        t.last_observed = stamp
        t.last_stamp = stamp
        if t.state == TrackState.COASTING or t.hits >= self.config.confirm_hits:
            t.state = TrackState.CONFIRMED
