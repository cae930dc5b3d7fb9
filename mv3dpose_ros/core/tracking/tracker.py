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
``gate_m + gate_growth_mps * (time since a 3D pose last matched the track)``: the paper's
tau = 0.2 m between consecutive frames, widened for tracks that were not located for a while
(single views keep a track observed but leave its depth open) and for low frame rates. Tracks
and poses left over are matched once more with the wider ``recovery_gate_m`` before new
tracks start, so one noisy pose does not fork a track. Tracks unobserved for more than
``lost_after_s`` are matched last (gate, then recovery gate) to the poses left: a stale track
with a wide gate never takes a person a fresh track follows.

Motion comes from the filtered state, never from raw observations: every track's joints run
through per-joint Kalman filters (``core.tracking.smoothing.JointKalman``, which rejects
single-frame outliers by an innovation gate), the track's pose is the filtered (held) pose, and its
body velocity is the inverse-variance mean of the filtered joint velocities. With ``predict`` each
track is moved by that velocity before matching, so walking people stay inside the gate at
low frame rates (at most ``max_predict_s`` of motion). A pose matched only by the wider
recovery gate updates the joints (through their own gates) but not the body velocity; a track
found after being lost restarts its velocity.

Life cycle: a new track is TENTATIVE, or CONFIRMED at once when the caller says it is well
supported (``confirm_at_birth``); after ``confirm_hits`` observations it is CONFIRMED; a
confirmed track that misses a set is COASTING until it is observed again (CONFIRMED). A track
not observed for more than ``max_coast_s`` is DELETED whatever the gate would accept: it takes
no part in matching any more. A TENTATIVE track that misses a set is DELETED, unless the set
missed cameras (``update(sparse=True)``) and the track was seen within ``tentative_coast_s``;
confirmation also needs ``confirm_views`` cameras behind its 3D poses, together
(``update(cameras=...)``), or four times the hits. Ids
start at 1 and are never reused by a tracker, not even after ``reset``.

Tracks are kept as a structure of arrays (``Tracks``), so an update costs the same few numpy
operations whatever the number of people.
"""

from dataclasses import dataclass, fields
from typing import Callable, Optional, Tuple, Union

from mv3dpose_ros.core.assignment import gated_assignment
from mv3dpose_ros.core.tracking.smoothing import JointKalman, KalmanUpdate
from mv3dpose_ros.core.types import Stamp, TrackState
import numpy as np

# Sums over x, y, z as a product with ones: several times cheaper than a last-axis sum of 3.
_XYZ = np.ones(3)

# Track states as int8 scalars: comparing an array with an IntEnum member costs ~6x more.
_TENTATIVE, _CONFIRMED, _COASTING = (np.int8(s) for s in (
    TrackState.TENTATIVE, TrackState.CONFIRMED, TrackState.COASTING))


#: A TENTATIVE track short of ``confirm_views`` cameras confirms after this many times
#: ``confirm_hits`` observations (see ``Tracker._confirmable``).
LONG_CONFIRM_FACTOR = 4

_NONE = np.zeros(0, dtype=np.int64)       # no rows (read-only)
_NONE.setflags(write=False)

BirthRule = Union[None, np.ndarray, Callable[[np.ndarray], np.ndarray]]


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
    recovery_gate_m: float = 0.5        # second-pass gate for tracks and poses left unmatched
    max_predict_s: float = 0.5          # motion extrapolated at most this long (then held)
    lost_after_s: float = 0.5           # tracks unobserved longer match only what is left
    tentative_coast_s: float = 0.0      # a TENTATIVE track survives sparse sets without it
    #                                     this long (``update(sparse=True)``)
    confirm_views: int = 0              # cameras behind a track's 3D poses to confirm it
    # per-joint Kalman filters (core.smoothing.JointKalman)
    accel_noise: float = 2.0            # white acceleration noise density [m^2/s^3]
    init_speed_mps: float = 1.0         # prior std of a new joint's velocity (starts at 0)
    gate_chi2: float = 16.3             # innovation gate (chi-square, 3 dof; 16.3 = 99.9 %)
    reinit_after: int = 2               # consecutive rejections before a joint restarts
    max_gap_s: float = 0.3              # a joint is held at most this long without update
    measurement_std_m: float = 0.03     # measurement std when the caller gives no variance


@dataclass
class Tracks:
    """The tracks of a tracker, one row each (T rows)."""

    ids: np.ndarray             # [T] int64, > 0
    state: np.ndarray           # [T] int8 TrackState
    pose: np.ndarray            # [T, J, 3] filtered joints, held in gaps (NaN: never seen)
    velocity: np.ndarray        # [T, 3] m/s filtered body velocity, NaN while unknown
    first_seen: np.ndarray      # [T] s
    last_observed: np.ndarray   # [T] s
    first_seen_ns: np.ndarray   # [T] int64 ns, the same stamps exactly
    last_observed_ns: np.ndarray    # [T] int64 ns
    last_matched: np.ndarray    # [T] s, last stamp a 3D pose matched (not a single view)
    cameras: np.ndarray         # [T, C] bool, the cameras behind its matched 3D poses, together
    hits: np.ndarray            # [T] observations
    missed: np.ndarray          # [T] consecutive updates without observation
    view_time: np.ndarray       # [T, C] s, the last stamp each camera saw it (-inf: never)
    confidence: np.ndarray      # [T, J] detector confidence of each joint's last observation

    @classmethod
    def empty(cls, num_joints: int, num_cameras: int = 0) -> 'Tracks':
        """Return zero tracks."""
        return cls(ids=np.zeros(0, dtype=np.int64), state=np.zeros(0, dtype=np.int8),
                   pose=np.zeros((0, num_joints, 3)), velocity=np.zeros((0, 3)),
                   first_seen=np.zeros(0), last_observed=np.zeros(0),
                   first_seen_ns=np.zeros(0, dtype=np.int64),
                   last_observed_ns=np.zeros(0, dtype=np.int64), last_matched=np.zeros(0),
                   cameras=np.zeros((0, num_cameras), dtype=bool),
                   hits=np.zeros(0, dtype=np.int64), missed=np.zeros(0, dtype=np.int64),
                   view_time=np.zeros((0, num_cameras)), confidence=np.zeros((0, num_joints)))

    def __len__(self) -> int:
        """Return the number of tracks."""
        return len(self.ids)

    def take(self, rows: np.ndarray) -> 'Tracks':
        """Return the tracks ``rows`` (index or mask) as a new ``Tracks``."""
        return Tracks(**{n: getattr(self, n)[rows] for n in _TRACK_FIELDS})

    def concat(self, other: 'Tracks') -> 'Tracks':
        """Return these tracks followed by ``other``."""
        return Tracks(**{n: np.concatenate((getattr(self, n), getattr(other, n)))
                         for n in _TRACK_FIELDS})

    def predicted(self, stamp: float, predict: bool = True, horizon_s: float = np.inf,
                  rows: Optional[np.ndarray] = None) -> np.ndarray:
        """
        Return ``[T, J, 3]`` poses moved by their velocity to ``stamp`` (when known).

        At most ``horizon_s`` of motion is extrapolated: a velocity says little about where
        a person lost for seconds went (the tracking gate grows with the time instead).
        ``rows``: only those tracks' poses, ``[N, J, 3]``.
        """
        pose, velocity, seen = self.pose, self.velocity, self.last_observed
        if rows is not None:
            pose, velocity, seen = pose[rows], velocity[rows], seen[rows]
        if not predict or not len(pose):
            return pose
        velocity = np.where(np.isnan(velocity), 0.0, velocity)               # unknown: stay
        elapsed = np.minimum(np.maximum(stamp - seen, -horizon_s), horizon_s)
        shift = velocity * elapsed[:, None]
        return pose + shift[:, None, :]


_TRACK_FIELDS = tuple(f.name for f in fields(Tracks))


@dataclass
class TrackUpdate:
    """What ``Tracker.update`` did, per live track (rows of ``Tracker.tracks``)."""

    detection: np.ndarray   # [T] index of the pose observed this update, -1 = none
    previous: np.ndarray    # [T] row of the track before the update, -1 = born now
    deleted: Tracks         # tracks deleted in this update (state DELETED), reported once
    filtered: KalmanUpdate  # the joint filters' estimates at this stamp, [T, J] rows
    measurement: np.ndarray             # [T, J, 3] the pose each track took (NaN: none)
    measurement_variance: np.ndarray    # [T, J] its per-axis variance [m^2] (NaN: none)
    complete: bool = False              # every live track took a pose


def filled(shape, value, dtype=float) -> np.ndarray:
    """Return ``np.full(shape, value, dtype)`` for a step's few-element arrays (4x cheaper)."""
    out = np.empty(shape, dtype)
    out.fill(value)
    return out


def padded(a: np.ndarray, value) -> np.ndarray:
    """Return ``a`` with one more row of ``value`` (row -1 of an index table: "none")."""
    out = np.empty((len(a) + 1,) + a.shape[1:], a.dtype)
    out[:-1] = a
    out[-1] = value
    return out


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


def median_joint_distance(a: np.ndarray, b: np.ndarray, min_shared_joints: int = 3
                          ) -> np.ndarray:
    """
    Return the ``[A, B]`` lower median distance of the joints two poses share.

    ``a [A, J, 3]``, ``b [B, J, 3]`` with NaN for missing joints.

    Robust where the mean is not: two noisy reconstructions of one person differ by a few
    limbs a lot and by the rest a little. Inf with fewer than ``min_shared_joints`` shared.
    """
    d = a[:, None] - b[None]
    diff = np.sqrt((d * d) @ _XYZ)                                  # [A, B, J], NaN if missing
    ok = np.isfinite(diff)
    n = ok.sum(axis=-1)
    ordered = np.sort(np.where(ok, diff, np.inf), axis=-1)          # missing joints last
    middle = np.maximum(n - 1, 0) // 2                              # the lower median
    flat = ordered.reshape(-1, ordered.shape[-1])                   # (take_along_axis is slow)
    med = flat[np.arange(len(flat)), middle.ravel()].reshape(middle.shape)
    return np.where(n >= min_shared_joints, med, np.inf)


class Tracker:
    """Assign 3D poses to tracks over time, filter their joints and run their life cycle."""

    def __init__(self, num_joints: int, config: Optional[TrackerConfig] = None,
                 num_cameras: int = 0) -> None:
        """Create an empty tracker for poses of ``num_joints`` joints from ``num_cameras``."""
        self.config = config or TrackerConfig()
        self.num_joints = int(num_joints)
        self.num_cameras = int(num_cameras)
        self.next_id = 1
        self._stamp: Optional[float] = None     # stamp of the last update
        self._none = Tracks.empty(self.num_joints, self.num_cameras)    # (read-only)
        for name in _TRACK_FIELDS:
            getattr(self._none, name).setflags(write=False)
        self._clear()

    def _clear(self) -> None:
        cfg = self.config
        self.tracks = Tracks.empty(self.num_joints, self.num_cameras)
        self.filter = JointKalman(self.num_joints, cfg.accel_noise, cfg.init_speed_mps,
                                  cfg.gate_chi2, cfg.reinit_after, cfg.max_gap_s)

    def reset(self) -> Tracks:
        """Drop all tracks (ids keep counting up) and return them marked DELETED."""
        dropped = self.tracks
        dropped.state = np.full(len(dropped), TrackState.DELETED, dtype=np.int8)
        self._clear()
        return dropped

    def update(self, poses: np.ndarray, stamp: Union[float, Stamp], can_birth: BirthRule = None,
               variance: Optional[np.ndarray] = None, confirm_at_birth: BirthRule = None,
               stamp_ns: Optional[int] = None, cameras: Optional[np.ndarray] = None,
               sparse: bool = True) -> TrackUpdate:
        """
        Match ``poses [D, J, 3]`` (NaN = missing joint) observed at ``stamp`` (s or ``Stamp``).

        Updates ``self.tracks`` (live tracks: matched, coasting, and new ones last) and returns
        which pose each live track took and the filtered joints. ``variance [D, J]`` is the
        per-axis measurement variance of each joint in m^2 (default ``measurement_std_m``^2).
        Unmatched poses start tracks only where ``can_birth [D]`` (default: all) holds and
        they have ``min_birth_joints`` joints; a new track is CONFIRMED at once where
        ``confirm_at_birth`` holds. Both rules may also be functions of the indices ``[N]`` of
        the candidate poses returning ``[N]`` booleans, so their work is only done when there
        are any. ``stamp_ns``: see ``Stamp.of``.
        ``cameras [D, C]`` are the cameras behind each pose: a TENTATIVE track is confirmed by
        ``confirm_hits`` only once ``confirm_views`` cameras stood behind its poses, together
        (a person a loaded rig only sees in sets of two cameras, different pairs, confirms;
        the same two detections again and again, a ghost's signature, do not). ``sparse``:
        some cameras are missing from these poses, so a TENTATIVE track not matched now may
        wait ``tentative_coast_s`` (a complete set that does not see it deletes it).
        """
        cfg = self.config
        at = Stamp.of(stamp, stamp_ns)
        stamp = at.s
        self._stamp = stamp
        tr = self.tracks
        num_t, num_d = len(tr), len(poses)
        det = filled(num_t, -1, int)
        recovered = np.zeros(num_t, dtype=np.int8)   # 1: recovery gate, 2: was lost
        unseen = np.maximum(stamp - tr.last_observed, 0.0)
        alive = unseen <= cfg.max_coast_s + 1e-9        # expired tracks take no part at all
        if num_t and num_d:
            cost = pose_distance(tr.predicted(stamp, cfg.predict, cfg.max_predict_s), poses,
                                 cfg.min_shared_joints)
            # The gate grows with the time since a 3D pose last matched: single views keep a
            # track alive but leave its depth uncertain.
            since = np.maximum(stamp - tr.last_matched, 0.0)
            gate = np.where(alive, cfg.gate_m + cfg.gate_growth_mps * since, -1.0)
            wide = np.maximum(gate, cfg.recovery_gate_m) if cfg.recovery_gate_m > 0 else None
            # A cascade: tracks seen lately first, with their gate and then (one noisy 3D pose
            # should not fork a person's track) the recovery gate; tracks lost for longer only
            # take what is left, so a stale track with a wide gate never takes a person that
            # a fresh track follows.
            recent = unseen <= cfg.lost_after_s + 1e-9
            lost = alive & ~recent
            fresh = alive & recent
            passes = [(fresh, gate, 0), (fresh, wide, 1)]
            if lost.any():
                passes += [(lost, gate, 2), (lost, wide, 2)]
            taken, matched = np.zeros(num_d, dtype=bool), 0      # matched: taken.sum()
            for group, limit, second in passes:
                if limit is None:
                    continue
                free_t = np.nonzero(group & (det < 0))[0]
                if not len(free_t) or matched == num_d:
                    continue
                if len(free_t) == num_t and not matched:
                    rows, cols = gated_assignment(cost, limit[:, None])
                    rows, cols = free_t[rows], cols
                else:
                    free_d = np.nonzero(~taken)[0]
                    r, c = gated_assignment(cost.take(free_t, axis=0).take(free_d, axis=1),
                                            limit[free_t, None])
                    rows, cols = free_t[r], free_d[c]
                det[rows] = cols
                taken[cols] = True
                recovered[rows] = second
                matched += len(rows)
                if matched == min(num_t, num_d):
                    break                   # every track, or every pose, is taken
        hit = det >= 0
        all_hit = bool(hit.all())
        if num_t:
            now = None
            if num_d and cameras is not None:
                now = cameras[det] if all_hit else cameras[np.maximum(det, 0)] & hit[:, None]
            # this set's confirmations count its pose's cameras and the earlier ones', each
            # on its own; the union counts from the next observation on
            self._observe(hit, at, all_hit, now)
            if now is not None:
                tr.cameras = tr.cameras | now
        if all_hit:                                 # the common case: nobody missed
            deleted, kept, live = self._none, np.arange(num_t), tr
        else:
            tentative = tr.state == _TENTATIVE
            wait = ~tentative | (sparse & (unseen <= cfg.tentative_coast_s + 1e-9))
            coast = ~hit & wait & alive
            keep = hit | coast
            tr.missed = np.where(hit, 0, tr.missed + 1)
            tr.state = np.where(coast & ~tentative, _COASTING, tr.state)
            if keep.all():                          # the next: those who missed coast
                deleted, kept, live = self._none, np.arange(num_t), tr
            else:
                deleted = tr.take(~keep)
                deleted.state[:] = TrackState.DELETED
                kept = np.nonzero(keep)[0]
                live = tr.take(kept)
                recovered = recovered[kept]
        new = _NONE
        matched = det[hit]
        if len(matched) < num_d:                    # else every pose continues a track
            born = np.ones(num_d, dtype=bool)
            born[matched] = False
            born &= np.isfinite(poses[..., 0]).sum(axis=1) >= cfg.min_birth_joints
            new = np.nonzero(_rule(can_birth, born))[0]
        det = det if all_hit else det[kept]
        previous = kept
        if len(new):
            confirm = np.zeros(len(new), dtype=bool)
            if confirm_at_birth is not None:
                confirm = _rule(confirm_at_birth, np.ones(len(new), dtype=bool), new)
            seen = cameras[new] if cameras is not None else None
            live = live.concat(self._births(len(new), at, confirm, seen))
            det = np.concatenate((det, new))
            previous = np.concatenate((kept, np.full(len(new), -1)))
            recovered = np.concatenate((recovered, np.zeros(len(new), dtype=np.int8)))
        self.tracks = live
        complete = bool((det >= 0).all())
        filtered, z, r = self._filter(poses, variance, det, previous, stamp, recovered,
                                      complete)
        return TrackUpdate(detection=det, previous=previous, deleted=deleted,
                           filtered=filtered, measurement=z, measurement_variance=r,
                           complete=complete)

    def _filter(self, poses: np.ndarray, variance: Optional[np.ndarray], det: np.ndarray,
                previous: np.ndarray, stamp: float, recovered: np.ndarray, complete: bool
                ) -> Tuple[KalmanUpdate, np.ndarray, np.ndarray]:
        """Run the joint filters of the live tracks; set their pose and body velocity."""
        cfg, tr = self.config, self.tracks
        if variance is None:
            variance = np.full(poses.shape[:2], cfg.measurement_std_m ** 2)
        if len(det) and complete:           # (complete: every track took a pose)
            z, r = poses.take(det, axis=0), variance.take(det, axis=0)
        else:                            # row D of the padded arrays is "not observed"
            z = padded(poses, np.nan).take(det, axis=0)
            r = padded(variance, np.nan).take(det, axis=0)
        self.filter.reindex(previous)
        out = self.filter.update(z, r, stamp)
        known = self.filter.count > 0
        tr.pose = np.where(known[..., None], self.filter.x, tr.pose)
        velocity = self.filter.body_velocity()
        if recovered.any():
            # not from a match outside the main gate; a track found after being lost has no
            # velocity worth keeping (its filters restart)
            velocity = np.where((recovered == 1)[:, None], tr.velocity, velocity)
            velocity = np.where((recovered == 2)[:, None], np.nan, velocity)
        tr.velocity = velocity
        return out, z, r

    def observe_views(self, rows: np.ndarray, stamp: Stamp,
                      located: Optional[np.ndarray] = None) -> None:
        """
        Count observations of tracks ``rows`` by single views, after their filters took them.

        At the stamp of the last ``update`` a track that no 3D pose matched is observed after
        all (CONFIRMED, not missed); a late view (older stamp) moves its last observation
        forward only. Pose and body velocity are re-read from the joint filters. Tracks
        ``located`` (views of two cameras fixed their depth) count as matched in 3D at
        ``stamp`` for the tracking gate.
        """
        rows = np.asarray(rows, dtype=np.int64)
        tr = self.tracks
        if located is not None and len(located):
            tr.last_matched[located] = np.maximum(tr.last_matched[located], stamp.s)
        if not len(rows):
            return
        newer = tr.last_observed[rows] < stamp.s
        now = rows[newer]
        tr.last_observed[now] = stamp.s
        tr.last_observed_ns[now] = stamp.ns
        current = now[tr.missed[now] > 0] if self._stamp == stamp.s else now[:0]
        tr.missed[current] = 0
        tr.hits[current] += 1
        earned = self._confirmable(tr.hits[current], tr.cameras[current].sum(axis=1))
        confirm = current[(tr.state[current] == _COASTING) | earned]
        tr.state[confirm] = _CONFIRMED
        self.refresh(rows)

    def refresh(self, rows: np.ndarray) -> None:
        """Re-read the pose and body velocity of tracks ``rows`` from their joint filters."""
        tr = self.tracks
        known = self.filter.count[rows] > 0
        tr.pose[rows] = np.where(known[..., None], self.filter.x[rows], tr.pose[rows])
        velocity = self.filter.body_velocity()[rows]
        tr.velocity[rows] = np.where(np.isnan(velocity), tr.velocity[rows], velocity)

    def _confirmable(self, hits: np.ndarray, cameras: np.ndarray) -> np.ndarray:
        """
        Tell which TENTATIVE tracks, of ``hits`` observations and ``cameras`` (counts), confirm.

        ``confirm_hits`` observations once ``confirm_views`` cameras stood behind its 3D poses;
        with fewer (a person the other cameras never see, or a ghost pairing the same two
        wrong detections) ``LONG_CONFIRM_FACTOR`` times as many: a ghost of a passing
        coincidence does not last that long, a person does.
        """
        cfg = self.config
        return ((hits >= cfg.confirm_hits) & (cameras >= cfg.confirm_views)) \
            | (hits >= LONG_CONFIRM_FACTOR * cfg.confirm_hits)

    def remove(self, rows: np.ndarray) -> Tracks:
        """Delete tracks ``rows`` now (e.g. a duplicate merged into another); return them."""
        keep = np.ones(len(self.tracks), dtype=bool)
        keep[rows] = False
        dead = self.tracks.take(~keep)
        dead.state[:] = TrackState.DELETED
        self.tracks = self.tracks.take(keep)
        self.filter.reindex(np.nonzero(keep)[0])
        return dead

    def add(self, poses: np.ndarray, stamp: Union[float, Stamp], variance: float,
            confirmed: bool = True) -> np.ndarray:
        """
        Start tracks of ``poses [N, J, 3]`` beside the live ones (people located by other means).

        Their joints start at ``poses`` with per-axis ``variance`` [m^2]; the other tracks'
        filters see ``stamp`` without an observation. Returns the new tracks' ids.
        """
        at = Stamp.of(stamp)
        poses = np.asarray(poses, dtype=float).reshape(-1, self.num_joints, 3)
        num_t, num_n = len(self.tracks), len(poses)
        self.tracks = self.tracks.concat(self._births(num_n, at, np.full(num_n, confirmed)))
        self.filter.reindex(np.concatenate((np.arange(num_t), np.full(num_n, -1))))
        z = np.full((num_t + num_n, self.num_joints, 3), np.nan)
        z[num_t:] = poses
        self.filter.update(z, np.full(z.shape[:2], float(variance)), at.s)
        self.refresh(np.arange(num_t, num_t + num_n))
        return self.tracks.ids[num_t:].copy()

    def _births(self, n: int, stamp: Stamp, confirm: np.ndarray,
                cameras: Optional[np.ndarray] = None) -> Tracks:
        if cameras is None:
            cameras = np.zeros((n, self.num_cameras), dtype=bool)
        instant = self._confirmable(np.ones(n, dtype=np.int64), cameras.sum(axis=1))
        state = np.where(confirm | instant, _CONFIRMED, _TENTATIVE).astype(np.int8)
        ids = np.arange(self.next_id, self.next_id + n, dtype=np.int64)
        self.next_id += n
        return Tracks(ids=ids, state=state, pose=np.full((n, self.num_joints, 3), np.nan),
                      velocity=np.full((n, 3), np.nan), first_seen=np.full(n, stamp.s),
                      last_observed=np.full(n, stamp.s),
                      first_seen_ns=np.full(n, stamp.ns, dtype=np.int64),
                      last_observed_ns=np.full(n, stamp.ns, dtype=np.int64),
                      last_matched=np.full(n, stamp.s), cameras=cameras,
                      hits=np.ones(n, dtype=np.int64), missed=np.zeros(n, dtype=np.int64),
                      view_time=np.full((n, self.num_cameras), -np.inf),
                      confidence=np.zeros((n, self.num_joints)))

    def _observe(self, hit: np.ndarray, stamp: Stamp, all_hit: bool = False,
                 cameras: Optional[np.ndarray] = None) -> None:
        """
        Count the observation of the tracks ``hit`` (mask; ``all_hit``: all).

        ``cameras [T, C]``: the cameras of the poses matched now (for confirmation).
        """
        stamp_ns, stamp = stamp.ns, stamp.s
        tr = self.tracks
        if all_hit:
            tr.hits = tr.hits + 1
            num_t = len(tr.ids)
            tr.last_observed = filled(num_t, stamp)
            tr.last_observed_ns = filled(num_t, stamp_ns, np.int64)
            tr.last_matched = filled(num_t, stamp)
            tr.missed = np.zeros(len(tr), dtype=np.int64)
        else:
            tr.hits = tr.hits + hit
            tr.last_observed = np.where(hit, stamp, tr.last_observed)
            tr.last_observed_ns = np.where(hit, stamp_ns, tr.last_observed_ns)
            tr.last_matched = np.where(hit, stamp, tr.last_matched)
        if (tr.state == _CONFIRMED).all():
            return                          # the steady state: nothing left to confirm
        count = tr.cameras.sum(axis=1)
        if cameras is not None:
            count = np.maximum(count, cameras.sum(axis=1))
        confirm = (tr.state == _COASTING) | self._confirmable(tr.hits, count)
        if not all_hit:
            confirm &= hit
        tr.state = np.where(confirm, _CONFIRMED, tr.state)


def _rule(rule: BirthRule, mask: np.ndarray, index: Optional[np.ndarray] = None) -> np.ndarray:
    """Apply a birth rule (array over all poses, or function of indices) to ``mask``."""
    mask = mask.copy()
    if callable(rule):
        if mask.any():
            rows = np.nonzero(mask)[0] if index is None else index[mask]
            mask[mask] = rule(rows)
    elif rule is not None:
        mask &= rule if index is None else np.asarray(rule)[index]
    return mask
