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
for low frame rates. Tracks and poses left over are matched once more with the wider
``recovery_gate_m`` before new tracks start, so one noisy pose does not fork a track. With
``predict`` each track is first moved by its velocity (constant
velocity of the whole body, estimated from the joints seen in consecutive observations), so
walking people stay inside the gate at low frame rates.

Life cycle: a new track is TENTATIVE; after ``confirm_hits`` observations it is CONFIRMED; a
confirmed track that misses a set is COASTING until it is observed again (CONFIRMED) or more
than ``max_coast_s`` pass without observation (DELETED). A TENTATIVE track that misses a set is
DELETED at once. Ids start at 1 and are never reused by a tracker, not even after ``reset``.

Tracks are kept as a structure of arrays (``Tracks``), so an update costs the same few numpy
operations whatever the number of people.
"""

from dataclasses import dataclass, fields
from typing import Callable, Optional, Union

from mv3dpose_ros.core.association import gated_assignment
from mv3dpose_ros.core.types import TrackState
import numpy as np

# Sums over x, y, z as a product with ones: several times cheaper than a last-axis sum of 3.
_XYZ = np.ones(3)

# Track states as int8 scalars: comparing an array with an IntEnum member costs ~6x more.
_TENTATIVE, _CONFIRMED, _COASTING = (np.int8(s) for s in (
    TrackState.TENTATIVE, TrackState.CONFIRMED, TrackState.COASTING))


_NONE = np.zeros(0, dtype=np.int64)       # no rows (read-only)
_NONE.setflags(write=False)


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
    velocity_smoothing: float = 0.5     # weight of the old velocity in its running average
    recovery_gate_m: float = 0.5        # second-pass gate for tracks and poses left unmatched


@dataclass
class Tracks:
    """The tracks of a tracker, one row each (T rows)."""

    ids: np.ndarray             # [T] int64, > 0
    state: np.ndarray           # [T] int8 TrackState
    pose: np.ndarray            # [T, J, 3] last observed joints (older values where missing)
    fresh: np.ndarray           # [T, J] joints refreshed by the last observation
    velocity: np.ndarray        # [T, 3] m/s, NaN until two observations
    first_seen: np.ndarray      # [T] s
    last_observed: np.ndarray   # [T] s
    hits: np.ndarray            # [T] observations
    missed: np.ndarray          # [T] consecutive updates without observation

    @classmethod
    def empty(cls, num_joints: int) -> 'Tracks':
        """Return zero tracks."""
        return cls(ids=np.zeros(0, dtype=np.int64), state=np.zeros(0, dtype=np.int8),
                   pose=np.zeros((0, num_joints, 3)), fresh=np.zeros((0, num_joints), bool),
                   velocity=np.zeros((0, 3)), first_seen=np.zeros(0),
                   last_observed=np.zeros(0), hits=np.zeros(0, dtype=np.int64),
                   missed=np.zeros(0, dtype=np.int64))

    def __len__(self) -> int:
        """Return the number of tracks."""
        return len(self.ids)

    def take(self, rows: np.ndarray) -> 'Tracks':
        """Return the tracks ``rows`` (index or mask) as a new ``Tracks``."""
        return Tracks(**{f.name: getattr(self, f.name)[rows] for f in fields(self)})

    def predicted(self, stamp: float, predict: bool = True) -> np.ndarray:
        """Return ``[T, J, 3]`` poses moved by their velocity to ``stamp`` (when known)."""
        if not predict or not len(self):
            return self.pose
        velocity = np.where(np.isnan(self.velocity), 0.0, self.velocity)     # unknown: stay
        shift = velocity * (stamp - self.last_observed)[:, None]
        return self.pose + shift[:, None, :]


@dataclass
class TrackUpdate:
    """What ``Tracker.update`` did, per live track (rows of ``Tracker.tracks``)."""

    detection: np.ndarray   # [T] index of the pose observed this update, -1 = none
    previous: np.ndarray    # [T] row of the track before the update, -1 = born now
    deleted: Tracks         # tracks deleted in this update (state DELETED), reported once


def centroid(poses: np.ndarray) -> np.ndarray:
    """Return the ``[..., 3]`` mean of the finite joints of ``[..., J, 3]`` poses (NaN if none)."""
    ok = np.isfinite(poses[..., 0])
    n = ok.sum(axis=-1)
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(ok[..., None], poses, 0.0).sum(axis=-2) / n[..., None]


def pose_distance(a: np.ndarray, b: np.ndarray, min_shared_joints: int = 3) -> np.ndarray:
    """
    Return the ``[A, B]`` tracking cost between poses ``a [A, J, 3]`` and ``b [B, J, 3]``.

    Mean joint distance over shared finite joints, or ground-plane centroid distance when fewer
    than ``min_shared_joints`` are shared (inf if either pose is empty).
    """
    d = a[:, None] - b[None]
    diff = np.sqrt((d * d) @ _XYZ)                                  # [A, B, J], NaN if missing
    ok = np.isfinite(diff)
    n = ok.sum(axis=-1)
    with np.errstate(invalid='ignore', divide='ignore'):
        mean = np.where(ok, diff, 0.0).sum(axis=-1) / n
        if (n < min_shared_joints).any():
            ca, cb = centroid(a)[:, :2], centroid(b)[:, :2]
            d = ca[:, None] - cb[None]
            ground = np.sqrt((d * d).sum(axis=-1))                  # x, y only
            mean = np.where(n >= min_shared_joints, mean, ground)
    return np.where(np.isfinite(mean), mean, np.inf)


class Tracker:
    """Assign 3D poses to tracks over time and run their life cycle."""

    def __init__(self, num_joints: int, config: Optional[TrackerConfig] = None) -> None:
        """Create an empty tracker for poses of ``num_joints`` joints."""
        self.config = config or TrackerConfig()
        self.num_joints = int(num_joints)
        self.tracks = Tracks.empty(self.num_joints)
        self.next_id = 1

    def reset(self) -> Tracks:
        """Drop all tracks (ids keep counting up) and return them marked DELETED."""
        dropped = self.tracks
        dropped.state = np.full(len(dropped), TrackState.DELETED, dtype=np.int8)
        self.tracks = Tracks.empty(self.num_joints)
        return dropped

    def update(self, poses: np.ndarray, stamp: float,
               can_birth: Union[None, np.ndarray, Callable[[np.ndarray], np.ndarray]] = None
               ) -> TrackUpdate:
        """
        Match ``poses [D, J, 3]`` (NaN = missing joint) observed at ``stamp`` seconds.

        Updates ``self.tracks`` (live tracks: matched, coasting, and new ones last) and returns
        which pose each live track took. Unmatched poses start tracks only where
        ``can_birth [D]`` (default: all) holds and they have ``min_birth_joints`` joints;
        ``can_birth`` may also be a function of the indices ``[N]`` of the unmatched poses
        returning ``[N]`` booleans, so its work is only done when there are any.
        """
        cfg = self.config
        tr = self.tracks
        num_t, num_d = len(tr), len(poses)
        det = np.full(num_t, -1)
        if num_t and num_d:
            cost = pose_distance(tr.predicted(stamp, cfg.predict), poses, cfg.min_shared_joints)
            gate = cfg.gate_m + cfg.gate_growth_mps * np.maximum(stamp - tr.last_observed, 0.0)
            rows, cols = gated_assignment(cost, gate[:, None])
            det[rows] = cols
            if cfg.recovery_gate_m > 0 and len(rows) < min(num_t, num_d):
                # Second chance for the leftovers with a wider gate, before new tracks are
                # started: one noisy 3D pose should not fork a person's track.
                free_t = np.nonzero(det < 0)[0]
                taken = np.zeros(num_d, dtype=bool)
                taken[cols] = True
                free_d = np.nonzero(~taken)[0]
                if len(free_t) and len(free_d):
                    r2, c2 = gated_assignment(cost[np.ix_(free_t, free_d)],
                                              np.maximum(gate[free_t, None], cfg.recovery_gate_m))
                    det[free_t[r2]] = free_d[c2]
        hit = det >= 0
        all_hit = bool(hit.all())
        if num_t:
            self._observe(hit, poses.take(det, axis=0) if all_hit else poses[det[hit]], stamp,
                          all_hit)
        if all_hit:                                 # the common case: nobody missed
            deleted, kept, live = Tracks.empty(self.num_joints), np.arange(num_t), tr
        else:
            coast = ~hit & (tr.state != _TENTATIVE) \
                & (stamp - tr.last_observed <= cfg.max_coast_s + 1e-9)
            keep = hit | coast
            tr.missed = np.where(hit, 0, tr.missed + 1)
            tr.state = np.where(coast, _COASTING, tr.state)
            deleted = tr.take(~keep)
            deleted.state[:] = TrackState.DELETED
            kept = np.nonzero(keep)[0]
            live = tr.take(kept)
        new = _NONE
        matched = det[hit]
        if len(matched) < num_d:                    # else every pose continues a track
            born = np.ones(num_d, dtype=bool)
            born[matched] = False
            born &= np.isfinite(poses[..., 0]).sum(axis=1) >= cfg.min_birth_joints
            if callable(can_birth):
                if born.any():
                    born[born] = can_birth(np.nonzero(born)[0])
            elif can_birth is not None:
                born &= can_birth
            new = np.nonzero(born)[0]
        self.tracks = live
        if not len(new):
            return TrackUpdate(detection=det if all_hit else det[kept], previous=kept,
                               deleted=deleted)
        self.tracks = _concat(live, self._births(poses[new], stamp))
        return TrackUpdate(detection=np.concatenate((det[kept], new)),
                           previous=np.concatenate((kept, np.full(len(new), -1))),
                           deleted=deleted)

    def _births(self, poses: np.ndarray, stamp: float) -> Tracks:
        n = len(poses)
        state = TrackState.CONFIRMED if self.config.confirm_hits <= 1 else TrackState.TENTATIVE
        ids = np.arange(self.next_id, self.next_id + n, dtype=np.int64)
        self.next_id += n
        return Tracks(ids=ids, state=np.full(n, state, dtype=np.int8), pose=poses.copy(),
                      fresh=np.isfinite(poses[..., 0]), velocity=np.full((n, 3), np.nan),
                      first_seen=np.full(n, stamp), last_observed=np.full(n, stamp),
                      hits=np.ones(n, dtype=np.int64), missed=np.zeros(n, dtype=np.int64))

    def _observe(self, hit: np.ndarray, obs: np.ndarray, stamp: float,
                 all_hit: bool = False) -> None:
        """Fold the observations ``obs`` into the tracks ``hit`` (mask; ``all_hit``: all)."""
        cfg = self.config
        tr = self.tracks
        if all_hit:
            old, fresh_old, prev = tr.pose, tr.fresh, tr.velocity
            dt = stamp - tr.last_observed
        else:
            old, fresh_old, prev = tr.pose[hit], tr.fresh[hit], tr.velocity[hit]
            dt = stamp - tr.last_observed[hit]
        ok = np.isfinite(obs[..., 0])
        both = ok & fresh_old
        n = both.sum(axis=1)
        with np.errstate(invalid='ignore', divide='ignore'):
            v = np.where(both[..., None], obs - old, 0.0).sum(axis=1) / (n * dt)[:, None]
        good = (n >= cfg.min_shared_joints) & (dt > 0)
        a = cfg.velocity_smoothing
        blended = np.where(np.isfinite(prev), a * prev + (1 - a) * v, v)
        vel = np.where(good[:, None], blended, prev)
        pose = np.where(ok[..., None], obs, old)
        if all_hit:
            tr.pose, tr.fresh, tr.velocity = pose, ok, vel
            tr.hits = tr.hits + 1
            tr.last_observed = np.full(len(tr), stamp)
            tr.missed = np.zeros(len(tr), dtype=np.int64)
        else:
            tr.pose, tr.fresh, tr.velocity = tr.pose.copy(), tr.fresh.copy(), tr.velocity.copy()
            tr.pose[hit], tr.fresh[hit], tr.velocity[hit] = pose, ok, vel
            tr.hits = tr.hits + hit
            tr.last_observed = np.where(hit, stamp, tr.last_observed)
        confirm = (tr.state == _COASTING) | (tr.hits >= cfg.confirm_hits)
        if not all_hit:
            confirm &= hit
        tr.state = np.where(confirm, _CONFIRMED, tr.state)


def _concat(a: Tracks, b: Tracks) -> Tracks:
    return Tracks(**{f.name: np.concatenate((getattr(a, f.name), getattr(b, f.name)))
                     for f in fields(a)})
