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
Every observation counts: 2D keypoints no triangulation used update the tracks as rays.

A person one camera of the set saw, a joint one view saw, a message late for its set
(``ViewUpdates.update_late``): each pose is matched to the track it projects onto and its
keypoints update that track's joint filters as rays (``JointKalman.update_rays``); see
``docs/sparse-views.md``. A view fixes a person across its ray, not along it: single views
keep a track observed for ``view_only_s`` after its last 3D match, or for as long as views of
two cameras within ``VIEW_PAIR_S`` keep fixing its depth.
"""

from collections import Counter
from typing import Optional, Tuple

from mv3dpose_ros.core.assignment import gated_assignment
from mv3dpose_ros.core.fusion.config import FusionConfig
from mv3dpose_ros.core.fusion.noise import MIN_VARIANCE, NoiseModel
from mv3dpose_ros.core.fusion.record import Points, Rays, SetRecord
from mv3dpose_ros.core.fusion.rig import Rig
from mv3dpose_ros.core.skeleton import Layout
from mv3dpose_ros.core.tracking.smoothing import RayUpdate
from mv3dpose_ros.core.tracking.tracker import Tracker
from mv3dpose_ros.core.types import JointState, Stamp, TrackState
import numpy as np

#: A late view counts for joints updated at most this long [s] after its stamp: free-running
#: cameras' views of one instant differ by a few milliseconds (half a 10 Hz period).
SAME_INSTANT_S = 0.05
#: Rays of two cameras at most this far apart in time [s] fix a person's depth (see
#: ``ViewUpdates.paired``).
VIEW_PAIR_S = 0.5
#: A single view's pose may be at most this much larger or smaller than the track projected
#: into its camera (about +-35 % in depth): a bystander on the same line of sight is not.
VIEW_SCALE_RATIO = 1.4

_TRIANGULATED = np.uint8(JointState.TRIANGULATED)
# No pose matched a track: (rows, cols, mirrored), as a solve without a feasible pair gives.
_NO_MATCH = (np.zeros(0, dtype=np.intp), np.zeros(0, dtype=np.intp), np.zeros(0, dtype=bool))
_TENTATIVE_TRACK = np.int8(TrackState.TENTATIVE)


class ViewUpdates:
    """Fold the 2D poses no triangulation used into the tracks they belong to."""

    def __init__(self, rig: Rig, layout: Layout, config: FusionConfig, tracker: Tracker,
                 noise: NoiseModel, counts: Counter) -> None:
        """Work on ``tracker``'s tracks; count 'view_updates' and 'late_views_used'."""
        self.rig, self.layout, self.config, self.tracker = rig, layout, config, tracker
        self._noise, self._counts = noise, counts
        self._mirror = layout.flip_permutation

    def update_set(self, s: SetRecord) -> Optional[Rays]:
        """
        Update the tracks with the 2D poses of set ``s`` that no triangulation used.

        In a ``sparse`` set (a camera missing), a member view of a track's 3D pose updates the
        joints no other view of it saw; a pose left over in a camera (seen by one camera, or
        not associated across views) is matched to a CONFIRMED or COASTING track that no 3D
        pose matched and updates all its joints. A track no 3D pose matched is observed when
        ``view_min_joints`` of its joints took a view and its depth is known (``view_only_s``
        since its last 3D match, or views of two cameras since, see ``paired``). Returns
        what the views did, None when nothing was left for them.
        """
        tr, pts = self.tracker.tracks, s.points
        num_n = pts.count
        if not num_n:
            return None
        upd, stamp, sparse = s.update, s.stamp, s.sparse
        assigned, from_member = s.track_members, s.track_seen
        if not sparse and np.count_nonzero(from_member) == num_n:
            return None                 # a complete set and no pose left over for a track
        has = upd.detection >= 0
        used = np.zeros(num_n + 1, dtype=bool)
        used[assigned[from_member]] = True
        free = np.nonzero(~used[:num_n])[0]
        # a pose left over goes to a track no 3D pose matched; to a TENTATIVE one only in a
        # set that misses a camera, where a new person's sets rarely hold two views (in a
        # complete set, a TENTATIVE track no pose matched is more likely a ghost)
        cand = np.nonzero(~has if sparse else (tr.state != _TENTATIVE_TRACK) & ~has)[0]
        flipped, took = None, False
        if len(free) and len(cand):
            assigned, flipped = assigned.copy(), np.zeros(assigned.shape, dtype=bool)
            pred = self._predicted(stamp.s, cand)
            cams = pts.camera.take(free)
            for c in sorted(set(cams.tolist())):
                rows_c = free[cams == c]
                rows, cols, flip = self._match(c, cand, pts.x.take(rows_c, axis=0), stamp.s,
                                               pred)
                if len(rows):
                    assigned[cand[rows], c] = rows_c[cols]
                    flipped[cand[rows], c] = flip
                    took = True
        if not (took or sparse and from_member.any()):
            return None                 # no pose left over took a track, none to complete
        pts4 = pts.x.take(assigned, axis=0)             # [T, C, J, 3]; -1: the missing row
        if flipped is not None and flipped.any():
            pts4[flipped] = pts4[flipped][:, self._mirror]
        vis = np.isfinite(pts4[..., 0])                 # [T, C, J]
        # a member view's joint counts only where no other view of the 3D pose saw it:
        # triangulated, it is in the 3D measurement already; seen by several views and not
        # triangulated, the views disagreed (the reprojection gate or the bone check)
        seen = (vis & from_member[..., None]).sum(axis=1)                   # [T, J]
        spent = upd.filtered.accepted | (seen > 1)
        use = vis & ~(from_member[..., None] & spent[:, None, :])
        if not sparse:
            # in a set of every camera, a joint only one camera saw is one the others could
            # not: occluded or doubtful (measured: with them, Campus x2 at full rate lost
            # 0.8 MOTA and switched an id more; in sparse sets they gain PCP)
            use &= ~from_member[..., None]
        if not use.any():
            return None
        return self._fold(s, assigned, pts4, use)

    def _fold(self, s: SetRecord, assigned: np.ndarray, pts4: np.ndarray,
              use: np.ndarray) -> Rays:
        """Run the ray updates ``use [T, C, J]`` of ``pts4``, camera by camera; observe."""
        cfg = self.config
        stamp, upd = s.stamp, s.update
        num_t, num_j = len(assigned), self.layout.num_joints
        rays = Rays(accepted=np.zeros((num_t, num_j), dtype=bool),
                    point=np.full((num_t, num_j, 3), np.nan),
                    variance=np.full((num_t, num_j), np.nan),
                    views=np.zeros((num_t, num_j), dtype=np.int64),
                    cameras=assigned >= 0)
        paired = np.zeros(num_t, dtype=bool)
        for c in np.nonzero(use.any(axis=(0, 2)))[0].tolist():
            rows = np.nonzero(use[:, c].any(axis=1))[0]
            res = self._ray_update(c, rows, np.where(use[rows, c][..., None], pts4[rows, c],
                                                     np.nan), stamp.s)
            acc = res.accepted
            seen = rows[acc.sum(axis=1) >= cfg.view_min_joints]
            paired[seen] |= self.paired(seen, c, stamp.s)
            rays.views[rows] += acc
            first = acc & ~rays.accepted[rows]
            rays.point[rows] = np.where(first[..., None], res.point, rays.point[rows])
            rays.variance[rows] = np.where(first, res.variance, rays.variance[rows])
            rays.accepted[rows] |= acc
        updated = np.nonzero(rays.accepted.any(axis=1))[0]
        if not len(updated):
            return rays
        has = upd.detection >= 0
        enough = (rays.accepted.sum(axis=1) >= cfg.view_min_joints) \
            & (self._depth_known(stamp.s) | paired)
        self.tracker.observe_views(np.nonzero(enough & ~has)[0], stamp,
                                   np.nonzero(paired & ~has)[0])
        self.tracker.refresh(updated)
        self._counts['view_updates'] += len(updated)
        kal, filt = upd.filtered, self.tracker.filter
        acc = rays.accepted
        kal.joints[acc] = filt.x[acc]
        kal.state[acc] = _TRIANGULATED
        kal.variance[acc] = filt.p_xx[acc]
        kal.accepted = kal.accepted | acc
        return rays

    def update_late(self, cam: int, points: Points, stamp: Stamp) -> int:
        """
        Update the tracks with camera ``cam``'s normalised poses of ``stamp`` (a late view).

        Each pose is associated with the CONFIRMED or COASTING track it projects onto (at
        ``stamp``, which may be older than the last step); returns the number of tracks whose
        joints it updated.
        """
        tr = self.tracker.tracks
        x = points.x[:points.count]
        cand = np.nonzero(tr.state != _TENTATIVE_TRACK)[0]
        if not len(x) or not len(cand):
            return 0
        rows, cols, flip = self._match(cam, cand, x, stamp.s, self._predicted(stamp.s, cand))
        if not len(rows):
            return 0
        pts = x.take(cols, axis=0)
        if flip.any():
            pts[flip] = pts[flip][:, self._mirror]
        res = self._ray_update(cam, cand[rows], pts, stamp.s)
        enough = res.accepted.sum(axis=1) >= self.config.view_min_joints
        paired = np.zeros(len(rows), dtype=bool)
        paired[enough] = self.paired(cand[rows][enough], cam, stamp.s)
        observed = cand[rows][enough & (self._depth_known(stamp.s)[cand[rows]] | paired)]
        self.tracker.observe_views(observed, stamp, cand[rows][paired])
        updated = cand[rows][res.accepted.any(axis=1)]
        if len(updated):
            self.tracker.refresh(updated)
            self._counts['late_views_used'] += 1
        return len(updated)

    def note(self, s: SetRecord) -> None:
        """Note this set's 3D matches in the tracks' per-camera view times."""
        np.copyto(self.tracker.tracks.view_time, s.stamp.s, where=s.track_seen)

    def paired(self, rows: np.ndarray, cam: int, stamp: float) -> np.ndarray:
        """
        Note that camera ``cam`` saw tracks ``rows`` at ``stamp``; tell which another saw too.

        Two cameras' rays within ``VIEW_PAIR_S`` fix a person's depth as one triangulation
        does, though they came in different sets (a rig whose inference cannot keep every
        camera in step): for those tracks the depth counts as measured now.
        """
        tr = self.tracker.tracks
        vt = tr.view_time
        vt[rows, cam] = np.maximum(vt[rows, cam], stamp)
        # views since the depth was last fixed (by a triangulation or by such a pair)
        since = tr.last_matched[rows, None]
        recent = ((vt[rows] >= stamp - VIEW_PAIR_S) & (vt[rows] > since)).sum(axis=1)
        return recent >= 2

    def _depth_known(self, stamp: float) -> np.ndarray:
        """
        Tell, per track, whether single views may still count as observing it at ``stamp``.

        A view fixes a person across its ray, not along it: after ``view_only_s`` without a
        3D match the depth may be off by a walk, so views still update the joints but no
        longer keep the track published (it coasts, keeps its id, and is found again by
        the next triangulated pose).
        """
        tr = self.tracker.tracks
        return stamp - tr.last_matched <= self.config.view_only_s + 1e-9

    def _predicted(self, stamp: float, rows: np.ndarray) -> np.ndarray:
        """Return the ``[N, J, 3]`` poses of tracks ``rows`` predicted to ``stamp``."""
        return self.tracker.tracks.predicted(stamp, self.config.tracking_prediction,
                                             self.tracker.config.max_predict_s, rows)

    def _match(self, cam: int, tracks: np.ndarray, poses: np.ndarray, stamp: float,
               predicted: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """
        Match normalised 2D poses ``[P, J, 3]`` of camera ``cam`` to tracks ``[N]`` (rows).

        The cost is the mean image distance (normalised units) between the track's predicted
        joints projected into the camera and the pose's, over at least ``min_shared_joints``
        joints; a mirrored pose (left/right swapped by the detector) is taken when it fits
        ``swap_ratio`` times better. The gate is the 3D tracking gate (grown with the time
        since a 3D pose matched the track) at the track's depth, plus 3 sigma of 2D noise.
        ``predicted`` are the poses of ``tracks`` at ``stamp``. Returns ``(rows into
        tracks, rows into poses, mirrored)``.
        """
        cfg, tr = self.config, self.tracker.tracks
        since = np.maximum(stamp - tr.last_matched[tracks], 0.0)
        gate_m = cfg.tracking_gate_m + cfg.tracking_gate_growth_mps * since
        pred = predicted                                                        # [N, J, 3]
        R, centre = self.rig.rotations[cam], self.rig.centres[cam]
        local = (pred - centre) @ R.T                                           # [N, J, 3]
        z = local[..., 2]
        mirror = self._mirror
        with np.errstate(invalid='ignore', divide='ignore'):
            front = z > 0.05
            proj = np.where(front[..., None], local[..., :2] / z[..., None], np.nan)
            if cfg.swap_check and len(self.layout.flip_pairs):
                # the poses as given and mirrored, in one pass
                num_p = len(poses)
                both = _image_cost(proj, np.concatenate((poses[..., :2], poses[:, mirror, :2])),
                                   cfg.min_shared_joints)                       # [N, 2P]
                cost, mirrored = both[:, :num_p], both[:, num_p:]
                flip = mirrored < cfg.swap_ratio * cost
                cost = np.where(flip, mirrored, cost)
            else:
                cost = _image_cost(proj, poses[..., :2], cfg.min_shared_joints)  # [N, P]
                flip = np.zeros(cost.shape, dtype=bool)
            depth = np.where(front, z, 0.0).sum(axis=1) / front.sum(axis=1)
        known = np.isfinite(depth)
        gate = np.where(known, gate_m / np.where(known, depth, 1.0) + 3 * self._noise.norm, -1.0)
        if not (cost < gate[:, None]).any():
            return _NO_MATCH                # (the size check below only removes pairs)
        with np.errstate(invalid='ignore', divide='ignore'):
            # A pose of the right place but the wrong size is another person on the same
            # line of sight (a bystander behind): its spread must match the projection's
            scale = _spread_ratio(proj, np.where(flip[..., None, None], poses[:, mirror, :2],
                                                 poses[..., :2]) if flip.any() else
                                  poses[..., :2])
            cost = np.where((scale > 1 / VIEW_SCALE_RATIO) & (scale < VIEW_SCALE_RATIO), cost,
                            np.inf)
        rows, cols = gated_assignment(cost, gate[:, None])
        return rows, cols, flip[rows, cols]

    def _ray_update(self, cam: int, rows: np.ndarray, points: np.ndarray,
                    stamp: float) -> RayUpdate:
        """Fold normalised 2D keypoints ``[N, J, 3]`` of camera ``cam`` into tracks ``rows``."""
        direction = points @ self.rig.rotations[cam]                # R^T p: world directions
        with np.errstate(invalid='ignore'):
            direction = direction / np.sqrt((direction * direction).sum(axis=-1))[..., None]
        return self.tracker.filter.update_rays(rows, self.rig.centres[cam], direction,
                                               self._noise.norm, stamp,
                                               self.config.view_gate_chi2, MIN_VARIANCE,
                                               SAME_INSTANT_S)


def _spread_ratio(proj: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """
    Return ``[N, P]`` size ratios of 2D poses ``[P, J, 2]`` (or ``[N, P, J, 2]``) to ``[N, J, 2]``.

    The size is the RMS distance of the joints both have from their mean, so a pose whose
    legs are hidden is compared with the projection's upper body only. NaN with < 2 shared.
    """
    # both sets of points at once: detected and projected, [2, N, P, J, 2]
    both = np.empty((2,) + (poses.shape if poses.ndim == 4 else (len(proj),) + poses.shape))
    both[0] = poses
    both[1] = proj[:, None]
    ok = np.isfinite(both[0, ..., 0]) & np.isfinite(both[1, ..., 0])     # [N, P, J]
    n = ok.sum(axis=-1)[..., None]
    with np.errstate(invalid='ignore', divide='ignore'):
        pts = np.where(ok[..., None], both, 0.0)
        centred = pts - pts.sum(axis=-2)[..., None, :] / n[..., None]
        sizes = np.sqrt((np.where(ok[..., None], centred, 0.0) ** 2).sum(axis=(-1, -2))
                        / n[..., 0])
        return np.where(n[..., 0] >= 2, sizes[0] / sizes[1], np.nan)


def _image_cost(proj: np.ndarray, poses: np.ndarray, min_joints: int) -> np.ndarray:
    """Return ``[N, P]`` mean distances of projected ``[N, J, 2]`` and detected ``[P, J, 2]``."""
    d = proj[:, None] - poses[None]
    dist = np.sqrt((d * d).sum(axis=-1))                              # [N, P, J], NaN: missing
    ok = np.isfinite(dist)
    n = ok.sum(axis=-1)
    mean = np.where(ok, dist, 0.0).sum(axis=-1) / np.maximum(n, 1)
    return np.where(n >= min_joints, mean, np.inf)
