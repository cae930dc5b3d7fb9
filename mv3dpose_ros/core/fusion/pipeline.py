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
The multi-view fusion pipeline: 2D poses of calibrated cameras in, tracked 3D skeletons out.

One ``Fusion.step`` per synchronised set of views runs the whole of Tanke & Gall's method:
normalise every keypoint once, associate poses across views with cameras taken in a
wide-angle-first order (``core.fusion.association``), triangulate with a reprojection gate, undo
single-view left/right swaps, reject implausible bones (``core.geometry.triangulation``), merge or
suppress duplicate 3D candidates, and track (``core.tracking.tracker``) with per-joint Kalman
filters (``core.tracking.smoothing.JointKalman``) whose measurement variance comes from the
geometry: the 2D noise per view in normalised units, times the joint's depth in the cameras that
saw it, squared, divided by their number. The 2D noise is estimated from the data as it comes in
(``noise_gain`` times a running mean of the per-set median reprojection error, corrected for
the degrees of freedom of the views), starting from ``measurement_noise_norm``: the filters
smooth as much as the detector's noise on this rig calls for, on any data set. The live node
and the offline command both call it, so their results agree frame for frame.

A new track that is well supported (``confirm_at_birth_ratio`` of the layout's joints
triangulated from at least min(3, cameras) views) is CONFIRMED from its first frame; others
wait for ``confirm_hits`` observations, one of them a pose of min(3, cameras - 1) views.

New tracks start only from candidates inside the rig's shared field of view (their centroid
in the images of ``min_birth_cameras_in_view`` cameras), detected by at least
``min_birth_view_ratio`` of the cameras of the set that should see them, and not within
``merge_distance_m`` of a track (a fragment of a tracked person); this keeps bystanders
outside the working volume and two-view "ghost" pairings from becoming tracks. Existing
tracks are updated by any candidate.

Every observation counts (``view_updates``): 2D keypoints no triangulation used (a person one
camera of the set saw, a joint one view saw, a message late for its set: ``update_view``)
update the tracks they belong to as rays (``JointKalman.update_rays``); see
``docs/sparse-views.md``. Tracks lost for up to ``max_coast_s`` are found again with their id,
and two tracks of one person are merged into the older.

Units: thresholds on image distances are in normalised image units (pixels / focal length;
0.045 = 45 px at f = 1000 px), 3D distances in metres, times in seconds (field names say so).
"""

from collections import Counter
from dataclasses import asdict, dataclass
import functools
from itertools import accumulate, compress
import logging
from typing import Dict, List, Mapping, Optional, Set, Tuple

from mv3dpose_ros.core.assignment import gated_assignment
from mv3dpose_ros.core.fusion.association import (associate_stacked, camera_order,
                                                  epipolar_norm_coefficients)
from mv3dpose_ros.core.geometry.camera import Camera, essential_matrices
from mv3dpose_ros.core.geometry.triangulation import (bone_length_limits, bone_outliers, dlt_basis,
                                                      swap_pairs, swapped_views,
                                                      triangulate_robust, Triangulation)
from mv3dpose_ros.core.skeleton import get_layout, Layout
from mv3dpose_ros.core.tracking.tracker import (centroid, median_joint_distance, Tracker,
                                                TrackerConfig, Tracks)
from mv3dpose_ros.core.types import JointState, PositionSource, Track, TrackState
import numpy as np

_LOG = logging.getLogger(__name__)

SMOOTHING_MODES = ('causal', 'none')
# Floor of a joint's measurement variance [m^2]: (5 mm)^2.
_MIN_VARIANCE = 0.005 ** 2
# Joint states as plain ints: comparing an array with an IntEnum member costs ~6x more.
_MISSING, _PREDICTED = int(JointState.MISSING), int(JointState.PREDICTED)
_TRIANGULATED = np.uint8(JointState.TRIANGULATED)
_TRACK_STATES = {int(s): s for s in TrackState}
_SOURCES = {int(s): s for s in PositionSource}
_TENTATIVE_TRACK = np.int8(TrackState.TENTATIVE)
# Frames two tracks must look like one person (close, no shared camera) before they merge.
_DUPLICATE_FRAMES = 3
#: A late view counts for joints updated at most this long [s] after its stamp: free-running
#: cameras' views of one instant differ by a few milliseconds (half a 10 Hz period).
SAME_INSTANT_S = 0.05
#: Rays of two cameras at most this far apart in time [s] fix a person's depth (see
#: ``Fusion._paired_views``).
VIEW_PAIR_S = 0.5
#: A single view's pose may be at most this much larger or smaller than the track projected
#: into its camera (about +-35 % in depth): a bystander on the same line of sight is not.
VIEW_SCALE_RATIO = 1.4
# Poses whose joint centres are further apart than the merge distance plus this [m] are not
# compared joint by joint (a cheap test first; a few wild joints move a centre, so generous).
_CENTRE_MARGIN_M = 1.0
# Extra per-axis variance of a root taken from the body instead of the hips [m^2]: (15 cm)^2.
_BODY_ROOT_VARIANCE = 0.15 ** 2


@dataclass
class FusionConfig:
    """Parameters of ``Fusion`` (all defaulted; units in the names, ``_norm`` = px / focal)."""

    # 2D input
    min_joint_confidence: float = 0.1       # keypoints below this count as missing
    min_pose_joints: int = 4                # 2D poses with fewer visible joints are ignored
    # association (paper: theta)
    epipolar_threshold_norm: float = 0.045  # mean symmetric epipolar distance gate
    min_shared_joints: int = 3              # joints two views must share for a valid cost
    max_reference_views: int = 4            # member views per candidate used in the cost
    min_views: int = 2                      # cameras a candidate needs to be triangulated
    # triangulation
    reprojection_gate_norm: float = 0.03    # max reprojection error of a view of a joint
    swap_check: bool = True                 # undo left/right swaps in single views
    swap_ratio: float = 0.5                 # swapped labels must fit this much better
    bone_check: bool = True                 # reject joints of implausibly long/short bones
    merge_distance_m: float = 0.25          # candidates closer than this are one person
    min_candidate_joints: int = 5           # triangulated joints a 3D pose needs
    # tracking (paper: tau)
    tracking_gate_m: float = 0.2            # mean joint distance to continue a track
    tracking_gate_growth_mps: float = 1.0   # gate widening per second since last observed
    tracking_recovery_gate_m: float = 0.5   # second-chance gate before starting a new track
    tracking_prediction: bool = True        # constant-velocity prediction of the root
    confirm_hits: int = 3                   # observations before a track is CONFIRMED
    max_coast_s: float = 3.0                # unobserved time before a track is DELETED: a
    #                                         person lost for less is found again with its id
    confirm_at_birth_ratio: float = 0.6     # a new track with this share of the layout's joints
    #                                         triangulated from >= min(3, cameras) views is
    #                                         CONFIRMED at once (> 1: never)
    publish_coast_s: float = 0.15           # COASTING tracks are published this long, then
    #                                         withheld until recovered or deleted
    min_birth_joints: int = 6               # triangulated joints to start a new track
    min_birth_cameras_in_view: int = 3      # cameras whose image must contain a new track's
    #                                         centroid (capped at cameras - 1): no tracks are
    #                                         started outside the rig's shared working volume
    min_birth_view_ratio: float = 0.5       # a new track's views / cameras that should see it
    # per-joint Kalman filters (always run: the tracker's motion comes from them)
    smoothing: str = 'causal'               # output 'causal' (filtered joints) or 'none'
    #                                         (accepted raw triangulations, held in gaps)
    measurement_noise_norm: float = 0.008   # 2D noise per view (px / focal) until estimated
    noise_gain: float = 1.5                 # 2D noise = gain * the noise estimated from the
    #                                         reprojection errors (0: measurement_noise_norm)
    accel_noise: float = 1.0                # white acceleration noise density [m^2/s^3]
    innovation_gate_chi2: float = 16.3      # reject an observation beyond this (3 dof, 99.9 %)
    reinit_after: int = 2                   # consecutive rejections before a joint restarts
    max_gap_s: float = 0.3                  # joints are held for at most this long
    # every observation counts: single views update the tracks they belong to
    view_updates: bool = True               # 2D keypoints no >= 2-view triangulation used
    #                                         update existing tracks as rays (False: only
    #                                         joints triangulated in one set do, the paper's)
    view_min_joints: int = 3                # joints a view must update to observe a track
    view_only_s: float = 1.0                # single views keep a track observed this long
    #                                         after its last triangulated match (depth drifts)
    tentative_coast_s: float = 0.25         # a TENTATIVE track outlives sets that miss a camera
    #                                         and it this long (not every sparse set sees a
    #                                         birth; a complete set without it deletes it)
    view_gate_chi2: float = 13.8            # ray innovation gate (chi-square, 2 dof, 99.9 %)

    def validate(self) -> None:
        """Raise ValueError naming the first out-of-range field."""
        positive = ('epipolar_threshold_norm', 'reprojection_gate_norm', 'tracking_gate_m',
                    'measurement_noise_norm', 'accel_noise', 'innovation_gate_chi2')
        non_negative = ('min_joint_confidence', 'swap_ratio', 'merge_distance_m',
                        'min_birth_view_ratio', 'tracking_gate_growth_mps',
                        'tracking_recovery_gate_m', 'max_coast_s', 'max_gap_s',
                        'confirm_at_birth_ratio', 'publish_coast_s', 'noise_gain',
                        'tentative_coast_s', 'view_only_s')
        at_least_one = ('min_pose_joints', 'min_shared_joints', 'max_reference_views',
                        'min_candidate_joints', 'confirm_hits', 'min_birth_joints',
                        'min_birth_cameras_in_view', 'reinit_after', 'view_min_joints')
        for name, value in asdict(self).items():
            if isinstance(value, bool) or name == 'smoothing':
                continue
            if not isinstance(value, (int, float)) or not np.isfinite(value):
                raise ValueError(f'FusionConfig.{name} must be a finite number, got {value!r}')
            if name in positive and value <= 0:
                raise ValueError(f'FusionConfig.{name} must be > 0, got {value}')
            if name in non_negative and value < 0:
                raise ValueError(f'FusionConfig.{name} must be >= 0, got {value}')
            if name in at_least_one and value < 1:
                raise ValueError(f'FusionConfig.{name} must be >= 1, got {value}')
        if self.min_views < 2:
            raise ValueError(f'FusionConfig.min_views must be >= 2 (triangulation needs two '
                             f'views), got {self.min_views}')
        if self.smoothing not in SMOOTHING_MODES:
            raise ValueError(f'FusionConfig.smoothing must be one of {SMOOTHING_MODES}, '
                             f'got {self.smoothing!r}')


class Fusion:
    """Fuse synchronised 2D poses of a calibrated rig into tracked 3D skeletons."""

    def __init__(self, cameras: Mapping[str, Camera], layout, config: Optional[FusionConfig] = None
                 ) -> None:
        """Precompute the rig geometry (essential matrices once per camera pair)."""
        self.config = config if config is not None else FusionConfig()
        self.config.validate()
        cfg = self.config
        if len(cameras) < 2:
            raise ValueError(f'Fusion needs at least two cameras, got {len(cameras)}: '
                             f'{sorted(cameras)}')
        self.layout: Layout = get_layout(layout)
        self.camera_names = tuple(cameras)
        self.cameras = [cameras[n] for n in self.camera_names]
        for name, cam in zip(self.camera_names, self.cameras):
            if not isinstance(cam, Camera):
                raise ValueError(f'camera {name!r} is a {type(cam).__name__}, not a Camera')
        self._index = {n: i for i, n in enumerate(self.camera_names)}
        num_c = len(self.cameras)
        self._essentials = essential_matrices(self.cameras)
        self._norm_coef = epipolar_norm_coefficients(self._essentials)
        self._order = camera_order(np.array([c.R[2] for c in self.cameras]))
        self._projections = np.stack([np.hstack([c.R, c.t[:, None]]) for c in self.cameras])
        self._basis = dlt_basis(self._projections)
        self._focal = np.array([c.focal for c in self.cameras])
        # Pixel -> normalised for distortion-free cameras: x = (u - cx - s y) / fx, y = ...
        self._k = np.array([[c.K[0, 0], c.K[0, 1], c.K[0, 2], c.K[1, 1], c.K[1, 2]]
                            for c in self.cameras])
        self._distorted = [c.has_distortion for c in self.cameras]
        self._bounds = np.array([_normalised_bounds(c) for c in self.cameras])   # [C, 4]
        self._birth_views = max(2, min(self.config.min_birth_cameras_in_view, num_c - 1))
        lay = self.layout
        self._bones = np.array(lay.bones, dtype=int).reshape(-1, 2)
        self._bone_lo, self._bone_hi = bone_length_limits(lay.joint_names, lay.bones)
        self._flip_pairs = np.array(lay.flip_pairs, dtype=int).reshape(-1, 2)
        try:
            self._root: Optional[Tuple[int, int]] = tuple(lay.root_joints)
        except ValueError:
            self._root = None
        cfg = self.config
        self.tracker = Tracker(lay.num_joints, TrackerConfig(
            gate_m=cfg.tracking_gate_m, gate_growth_mps=cfg.tracking_gate_growth_mps,
            recovery_gate_m=cfg.tracking_recovery_gate_m,
            min_shared_joints=cfg.min_shared_joints, predict=cfg.tracking_prediction,
            confirm_hits=cfg.confirm_hits, max_coast_s=cfg.max_coast_s,
            min_birth_joints=cfg.min_birth_joints, accel_noise=cfg.accel_noise,
            gate_chi2=cfg.innovation_gate_chi2, reinit_after=cfg.reinit_after,
            max_gap_s=cfg.max_gap_s, tentative_coast_s=cfg.tentative_coast_s,
            lost_after_s=max(cfg.publish_coast_s, 0.3),
            confirm_views=max(2, min(3, num_c - 1))), num_cameras=num_c)
        self._depth_rows = np.stack([np.append(c.R[2], c.t[2]) for c in self.cameras])  # [C, 4]
        self._strong_views = min(3, num_c)
        self._noise_views = min(3, num_c)         # 2-view residuals say little about noise
        self._noise_est, self._noise_sets, self._noise_calls = cfg.measurement_noise_norm, 0, 0
        self._confirm_joints = cfg.confirm_at_birth_ratio * lay.num_joints
        self._last_stamp: Optional[float] = None
        self._warned: Set[str] = set()
        num_j = lay.num_joints
        self._confidence = np.zeros((0, num_j))           # last observed confidence per track
        self._view_time = np.zeros((0, num_c))            # per track and camera: last stamp
        #                                                   it saw the track [s]
        #: 3D poses ``[K, J, 3]`` triangulated in the last step, before tracking.
        self.last_poses = np.empty((0, num_j, 3))
        #: ``[K, C]`` index of the input 2D pose (in ``views[camera]``) behind each of
        #: ``last_poses`` per camera (rig order), -1 where a camera did not contribute.
        self.last_members = np.zeros((0, len(self.cameras)), dtype=int)
        self._info: Dict[str, float] = {}
        self._info_tri: Optional[Triangulation] = None
        self._x, self._offsets = np.full((1, num_j, 3), np.nan), (0,) * (num_c + 1)
        self._centres = np.array([c.center for c in self.cameras])
        self._rotations = np.array([c.R for c in self.cameras])
        self._flip = self.layout.flip_permutation
        self._duplicates: Dict[Tuple[int, int], int] = {}   # id pair -> frames alike
        #: Counters since construction: tracks updated by single views in a step
        #: ('view_updates'), late views used ('late_views_used'), tracks found again after
        #: they stopped being published ('recovered'), duplicates merged ('merged_tracks').
        self.counts: Counter = Counter()

    # ------------------------------------------------------------------ public API
    def reset(self) -> List[Track]:
        """Clear all tracks and filters; return their DELETED tombstones (ids keep counting)."""
        dropped = self._tombstones(self.tracker.reset())
        self._confidence = np.zeros((0, self.layout.num_joints))
        self._view_time = np.zeros((0, len(self.cameras)))
        self._duplicates.clear()
        self._last_stamp = None
        return dropped

    def step(self, views: Mapping[str, np.ndarray], stamp: float,
             stamp_ns: Optional[int] = None) -> List[Track]:
        """
        Fuse one synchronised set of views taken at ``stamp`` seconds into tracks.

        ``views`` maps camera name -> ``[P, J, 3]`` raw-pixel 2D poses (x, y, confidence;
        confidence 0 = missing joint) in the layout's joint order; cameras may be absent and
        P may be 0. Returns the live tracks (TENTATIVE, CONFIRMED, COASTING) in id order, then
        the tracks deleted in this step, once, as DELETED tombstones. Bad views (unknown
        camera, wrong shape) are skipped with a logged warning naming them. A stamp earlier
        than the previous one resets the tracks first (their tombstones come with this step).
        ``stamp_ns`` is the same stamp in integer nanoseconds (default: ``stamp`` rounded); the
        tracks' ``first_seen_ns`` / ``last_observed_ns`` are copies of it, exactly.
        """
        cfg = self.config
        stamp = float(stamp)
        stamp_ns = int(round(stamp * 1e9)) if stamp_ns is None else int(stamp_ns)
        tombs: List[Track] = []
        if self._last_stamp is not None and stamp < self._last_stamp:
            self._warn('time', f'stamp went back from {self._last_stamp:.6f} s to {stamp:.6f} s:'
                       ' tracks reset (warned once)')
            tombs = self.reset()
        self._last_stamp = stamp
        tri, members = self._reconstruct(views)
        self.last_poses = tri.joints

        def can_birth(rows: np.ndarray) -> np.ndarray:
            # only for poses left unmatched: inside the shared field of view, well supported
            # by the cameras of this set that should see it (a camera whose message missed
            # the set cannot have seen anyone)
            inside = self.cameras_in_view(tri.joints[rows], per_camera=True)     # [N, C]
            present = np.array([n in views for n in self.camera_names])
            views_ = (members[rows] >= 0).sum(axis=1)
            ok = (inside.sum(axis=1) >= self._birth_views) \
                & (views_ >= self.config.min_birth_view_ratio * (inside & present).sum(axis=1))
            if ok.any() and len(self.tracker.tracks):
                # a fragment of a tracked person (its views split from the rest by the
                # association) is no one new: a track of it would be a duplicate
                ok[ok] = ~self._near_a_track(tri.joints[rows[ok]], stamp)
            return ok

        def strong(rows: np.ndarray) -> np.ndarray:
            # confirmed at once: enough joints triangulated from min(3, cameras) views
            well_seen = (tri.num_views[rows] >= self._strong_views).sum(axis=1)
            return well_seen >= self._confirm_joints

        self._estimate_noise(tri)
        variance = self.measurement_variance(tri)
        merged = self._merge_duplicates() if self._duplicates else None
        tr = self.tracker.tracks
        lost = tr.ids[stamp - tr.last_observed > cfg.publish_coast_s + 1e-9]
        sparse = any(views.get(n) is None for n in self.camera_names)
        upd = self.tracker.update(tri.joints, stamp, can_birth, variance, strong, stamp_ns,
                                  cameras=members >= 0, sparse=sparse)
        self._note_views(upd, members, stamp)
        rays = None
        if cfg.view_updates and len(self.tracker.tracks):
            rays = self._update_from_views(upd, members, stamp, stamp_ns, sparse)
        tr = self.tracker.tracks
        if len(lost):
            back = tr.ids[tr.last_observed == stamp]
            self.counts['recovered'] += int(np.isin(back, lost).sum())
        out = self._outputs(upd, tri, members, variance, stamp, rays)
        self._count_duplicates(rays, upd, members)
        if merged is not None:
            tombs += self._tombstones(merged)
        return out + tombs + self._tombstones(upd.deleted)

    def update_view(self, camera: str, poses: np.ndarray, stamp: float,
                    stamp_ns: Optional[int] = None) -> int:
        """
        Update the tracks with one camera's 2D poses taken at ``stamp`` (a late message).

        For views that missed their synchronised set: each pose is associated with the
        CONFIRMED or COASTING track it projects onto (at ``stamp``, which may be older than
        the last step) and its keypoints update that track's joint filters as rays. Nothing
        is born and nothing is output; the next ``step`` reports the tracks. Returns the
        number of tracks updated (0 with ``view_updates`` off, for an unknown camera, or when
        every joint it saw was updated after ``stamp``: it brings nothing new).
        """
        stamp = float(stamp)
        stamp_ns = int(round(stamp * 1e9)) if stamp_ns is None else int(stamp_ns)
        tr = self.tracker.tracks
        if not self.config.view_updates or not len(tr) or camera not in self._index:
            if camera not in self._index:
                self._warn('cam:' + str(camera), f'view of unknown camera {camera!r} ignored '
                           f'(rig cameras: {", ".join(self.camera_names)})')
            return 0
        if self._last_stamp is not None and stamp < self._last_stamp - self.config.max_coast_s:
            return 0                     # older than anything the tracks still hold
        x, _, offsets, _ = self._prepare({camera: poses})
        c = self._index[camera]
        lo, hi = offsets[c], offsets[c + 1]
        cand = np.nonzero(tr.state != _TENTATIVE_TRACK)[0]
        if hi == lo or not len(cand):
            return 0
        rows, cols, flip = self._match_view(c, cand, x[lo:hi], stamp, self._predicted(stamp))
        if not len(rows):
            return 0
        pts = x[lo:hi].take(cols, axis=0)
        if flip.any():
            pts[flip] = pts[flip][:, self.layout.flip_permutation]
        res = self._ray_update(c, cand[rows], pts, stamp)
        enough = res.accepted.sum(axis=1) >= self.config.view_min_joints
        paired = np.zeros(len(rows), dtype=bool)
        paired[enough] = self._paired_views(cand[rows][enough], c, stamp)
        observed = cand[rows][enough & (self._depth_known(stamp)[cand[rows]] | paired)]
        self.tracker.observe_views(observed, stamp, stamp_ns, cand[rows][paired])
        updated = cand[rows][res.accepted.any(axis=1)]
        if len(updated):
            self.tracker.refresh(updated)
            self.counts['late_views_used'] += 1
        return len(updated)

    # ------------------------------------------------------------------ single views
    def _update_from_views(self, upd, members: np.ndarray, stamp: float, stamp_ns: int,
                           sparse: bool) -> Optional['_Rays']:
        """
        Update the tracks with the 2D poses that no triangulation used (``view_updates``).

        In a ``sparse`` set (a camera missing), a member view of a track's 3D pose updates the
        joints no other view of it saw; a pose left over in a camera (seen by one camera, or
        not associated across views) is matched to a CONFIRMED or COASTING track that no 3D
        pose matched and updates all its joints. A track no 3D pose matched is observed when
        ``view_min_joints`` of its joints took a view and its depth is known (``view_only_s``
        since its last 3D match, or views of two cameras since, see ``_paired_views``).
        """
        cfg, tr = self.config, self.tracker.tracks
        x, offsets = self._x, self._offsets
        num_n, num_t = offsets[-1], len(tr)
        if not num_n:
            return None
        det = upd.detection
        assigned = np.full((num_t, len(self.cameras)), -1)
        has = det >= 0
        if has.any():
            assigned[has] = members[det[has]]
        from_member = assigned >= 0
        used = np.zeros(num_n + 1, dtype=bool)
        used[assigned[from_member]] = True
        # a pose left over goes to a track no 3D pose matched; to a TENTATIVE one only in a
        # set that misses a camera, where a new person's sets rarely hold two views (in a
        # complete set, a TENTATIVE track no pose matched is more likely a ghost)
        eligible = ~has if sparse else (tr.state != _TENTATIVE_TRACK) & ~has
        flipped = np.zeros((num_t, len(self.cameras)), dtype=bool)
        pred = None
        for c, (lo, hi) in enumerate(zip(offsets, offsets[1:])):
            if hi == lo or used[lo:hi].all():
                continue
            free = lo + np.nonzero(~used[lo:hi])[0]
            cand = np.nonzero(eligible & (assigned[:, c] < 0))[0]
            if len(cand):
                pred = self._predicted(stamp) if pred is None else pred
                rows, cols, flip = self._match_view(c, cand, x.take(free, axis=0), stamp, pred)
                assigned[cand[rows], c] = free[cols]
                flipped[cand[rows], c] = flip
        if not sparse and not (assigned > np.where(from_member, assigned, -1)).any():
            return None                  # a complete set and no pose left over for a track
        if not (assigned >= 0).any():
            return None
        pts = x.take(assigned, axis=0)                  # [T, C, J, 3]; -1: the missing row
        if flipped.any():
            pts[flipped] = pts[flipped][:, self._flip]
        vis = np.isfinite(pts[..., 0])                  # [T, C, J]
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
        num_j = self.layout.num_joints
        rays = _Rays(accepted=np.zeros((num_t, num_j), dtype=bool),
                     point=np.full((num_t, num_j, 3), np.nan),
                     variance=np.full((num_t, num_j), np.nan),
                     views=np.zeros((num_t, num_j), dtype=np.int64),
                     cameras=assigned >= 0)
        paired = np.zeros(num_t, dtype=bool)
        for c in np.nonzero(use.any(axis=(0, 2)))[0].tolist():
            rows = np.nonzero(use[:, c].any(axis=1))[0]
            res = self._ray_update(c, rows, np.where(use[rows, c][..., None], pts[rows, c],
                                                     np.nan), stamp)
            acc = res.accepted
            seen = rows[acc.sum(axis=1) >= cfg.view_min_joints]
            paired[seen] |= self._paired_views(seen, c, stamp)
            rays.views[rows] += acc
            first = acc & ~rays.accepted[rows]
            rays.point[rows] = np.where(first[..., None], res.point, rays.point[rows])
            rays.variance[rows] = np.where(first, res.variance, rays.variance[rows])
            rays.accepted[rows] |= acc
        updated = np.nonzero(rays.accepted.any(axis=1))[0]
        if not len(updated):
            return rays
        enough = (rays.accepted.sum(axis=1) >= cfg.view_min_joints) \
            & (self._depth_known(stamp) | paired)
        self.tracker.observe_views(np.nonzero(enough & ~has)[0], stamp, stamp_ns,
                                   np.nonzero(paired & ~has)[0])
        self.tracker.refresh(updated)
        self.counts['view_updates'] += len(updated)
        kal, filt = upd.filtered, self.tracker.filter
        acc = rays.accepted
        kal.joints[acc] = filt.x[acc]
        kal.state[acc] = _TRIANGULATED
        kal.variance[acc] = filt.p_xx[acc]
        kal.accepted = kal.accepted | acc
        return rays

    def _near_a_track(self, poses: np.ndarray, stamp: float) -> np.ndarray:
        """Tell which 3D poses ``[N, J, 3]`` lie within ``merge_distance_m`` of a track."""
        cfg = self.config
        pred = self._predicted(stamp)
        a, b = centroid(poses), centroid(pred)        # cheap first: centres far apart
        d = a[:, None] - b[None]
        with np.errstate(invalid='ignore'):
            maybe = ((d * d).sum(axis=-1)
                     < (cfg.merge_distance_m + _CENTRE_MARGIN_M) ** 2).any(axis=1)
        out = np.zeros(len(poses), dtype=bool)
        if maybe.any():
            near = median_joint_distance(poses[maybe], pred, cfg.min_shared_joints)
            out[maybe] = (near < cfg.merge_distance_m).any(axis=1)
        return out

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

    def _note_views(self, upd, members: np.ndarray, stamp: float) -> None:
        """Follow the tracks' rows with the per-camera view times; note this set's 3D ones."""
        previous = upd.previous
        old = self._view_time
        if len(previous) != len(old) or previous.tolist() != list(range(len(old))):
            self._view_time = np.full((len(previous), len(self.cameras)), -np.inf)
            kept = previous >= 0
            if kept.any():
                self._view_time[kept] = old[previous[kept]]
        det = upd.detection
        has = det >= 0
        if has.any():
            rows = np.nonzero(has)[0]
            seen = members[det[rows]] >= 0
            self._view_time[rows] = np.where(seen, stamp, self._view_time[rows])

    def _paired_views(self, rows: np.ndarray, cam: int, stamp: float) -> np.ndarray:
        """
        Note that camera ``cam`` saw tracks ``rows`` at ``stamp``; tell which another saw too.

        Two cameras' rays within ``VIEW_PAIR_S`` fix a person's depth as one triangulation
        does, though they came in different sets (a rig whose inference cannot keep every
        camera in step): for those tracks the depth counts as measured now.
        """
        vt = self._view_time
        vt[rows, cam] = np.maximum(vt[rows, cam], stamp)
        # views since the depth was last fixed (by a triangulation or by such a pair)
        since = self.tracker.tracks.last_matched[rows, None]
        recent = ((vt[rows] >= stamp - VIEW_PAIR_S) & (vt[rows] > since)).sum(axis=1)
        return recent >= 2

    def _predicted(self, stamp: float) -> np.ndarray:
        """Return the ``[T, J, 3]`` poses of the tracks predicted to ``stamp``."""
        return self.tracker.tracks.predicted(stamp, self.config.tracking_prediction,
                                             self.tracker.config.max_predict_s)

    def _match_view(self, cam: int, tracks: np.ndarray, poses: np.ndarray, stamp: float,
                    predicted: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
        """
        Match normalised 2D poses ``[P, J, 3]`` of camera ``cam`` to tracks ``[N]`` (rows).

        The cost is the mean image distance (normalised units) between the track's predicted
        joints projected into the camera and the pose's, over at least ``min_shared_joints``
        joints; a mirrored pose (left/right swapped by the detector) is taken when it fits
        ``swap_ratio`` times better. The gate is the 3D tracking gate (grown with the time
        since a 3D pose matched the track) at the track's depth, plus 3 sigma of 2D noise.
        ``predicted`` are all tracks' poses at ``stamp``. Returns ``(rows into tracks, rows
        into poses, mirrored)``.
        """
        cfg, tr = self.config, self.tracker.tracks
        pred = predicted[tracks]                                                # [N, J, 3]
        R, centre = self._rotations[cam], self._centres[cam]
        local = (pred - centre) @ R.T                                           # [N, J, 3]
        z = local[..., 2]
        with np.errstate(invalid='ignore', divide='ignore'):
            front = z > 0.05
            proj = np.where(front[..., None], local[..., :2] / z[..., None], np.nan)
            cost = _image_cost(proj, poses[..., :2], cfg.min_shared_joints)     # [N, P]
            flip = np.zeros(cost.shape, dtype=bool)
            if cfg.swap_check and len(self._flip_pairs):
                mirrored = _image_cost(proj, poses[:, self._flip, :2], cfg.min_shared_joints)
                flip = mirrored < cfg.swap_ratio * cost
                cost = np.where(flip, mirrored, cost)
            depth = np.where(front, z, 0.0).sum(axis=1) / front.sum(axis=1)
            # A pose of the right place but the wrong size is another person on the same
            # line of sight (a bystander behind): its spread must match the projection's
            scale = _spread_ratio(proj, np.where(flip[..., None, None], poses[:, self._flip, :2],
                                                 poses[..., :2]) if flip.any() else
                                  poses[..., :2])
            cost = np.where((scale > 1 / VIEW_SCALE_RATIO) & (scale < VIEW_SCALE_RATIO), cost,
                            np.inf)
        since = np.maximum(stamp - tr.last_matched[tracks], 0.0)
        gate_m = cfg.tracking_gate_m + cfg.tracking_gate_growth_mps * since
        gate = np.where(np.isfinite(depth), gate_m / np.where(np.isfinite(depth), depth, 1.0)
                        + 3 * self.noise_norm, -1.0)
        rows, cols = gated_assignment(cost, gate[:, None])
        return rows, cols, flip[rows, cols]

    def _ray_update(self, cam: int, rows: np.ndarray, points: np.ndarray, stamp: float):
        """Fold normalised 2D keypoints ``[N, J, 3]`` of camera ``cam`` into tracks ``rows``."""
        direction = points @ self._rotations[cam]                  # R^T p: world directions
        with np.errstate(invalid='ignore'):
            direction = direction / np.sqrt((direction * direction).sum(axis=-1))[..., None]
        return self.tracker.filter.update_rays(rows, self._centres[cam], direction,
                                               self.noise_norm, stamp,
                                               self.config.view_gate_chi2, _MIN_VARIANCE,
                                               SAME_INSTANT_S)

    # ------------------------------------------------------------------ duplicates
    def _count_duplicates(self, rays: Optional['_Rays'], upd, members: np.ndarray) -> None:
        """
        Count, per pair of published tracks, the consecutive steps they look like one person.

        Alike: median joint distance below ``merge_distance_m`` and no camera seeing both in
        this step (one person tracked twice from disjoint views; two people side by side are
        seen by the same cameras). ``_merge_duplicates`` acts on the count next step.
        """
        cfg, tr = self.config, self.tracker.tracks
        live = np.nonzero(tr.state != _TENTATIVE_TRACK)[0]
        if len(live) < 2 or cfg.merge_distance_m <= 0:
            self._duplicates.clear()
            return
        cams = np.zeros((len(tr), len(self.cameras)), dtype=bool)
        det = upd.detection
        has = det >= 0
        if has.any():
            cams[has] = members[det[has]] >= 0
        if rays is not None:
            cams |= rays.cameras
        # pairs no camera saw both of now (two people side by side share cameras): the
        # common case of a complete set has none, and costs one product
        c = cams[live].astype(np.float64)
        apart = (c @ c.T == 0) & _upper_triangle(len(live))
        if not apart.any():
            self._duplicates.clear()
            return
        # the centres next (cheap): mean joint distances below the merge distance need
        # centres within about as much
        centre = centroid(tr.pose[live])
        d = centre[:, None] - centre[None]
        with np.errstate(invalid='ignore'):
            apart &= (d * d).sum(axis=-1) < (cfg.merge_distance_m + _CENTRE_MARGIN_M) ** 2
        if not apart.any():
            self._duplicates.clear()
            return
        dist = median_joint_distance(tr.pose[live], tr.pose[live], cfg.min_shared_joints)
        close = (dist < cfg.merge_distance_m) & apart
        ids = tr.ids.tolist()
        alike = {}
        for i, j in zip(*np.nonzero(close)):
            key = (ids[live[i]], ids[live[j]])
            alike[key] = self._duplicates.get(key, 0) + 1
        self._duplicates = alike

    def _merge_duplicates(self) -> Optional[Tracks]:
        """Delete the younger of each pair alike for ``_DUPLICATE_FRAMES`` steps (or None)."""
        tr = self.tracker.tracks
        row = {tid: r for r, tid in enumerate(tr.ids.tolist())}
        drop = set()
        for (a, b), frames in sorted(self._duplicates.items()):
            if frames >= _DUPLICATE_FRAMES and a in row and b in row \
                    and a not in drop and b not in drop:
                older = a if (tr.first_seen[row[a]], a) <= (tr.first_seen[row[b]], b) else b
                drop.add(b if older == a else a)
        self._duplicates = {k: n for k, n in self._duplicates.items() if not set(k) & drop}
        if not drop:
            return None
        rows = np.array(sorted(row[d] for d in drop))
        keep = np.ones(len(tr), dtype=bool)
        keep[rows] = False
        self._confidence = self._confidence[keep] if len(self._confidence) == len(tr) \
            else self._confidence
        self._view_time = self._view_time[keep]
        self.counts['merged_tracks'] += len(rows)
        return self.tracker.remove(rows)

    @property
    def noise_norm(self) -> float:
        """Return the 2D noise per view (normalised units) behind the measurement variance."""
        cfg = self.config
        if cfg.noise_gain <= 0 or self._noise_sets == 0:
            return cfg.measurement_noise_norm
        return cfg.noise_gain * self._noise_est

    def _estimate_noise(self, tri: Triangulation) -> None:
        """Fold this set's median reprojection error into the running 2D noise estimate."""
        self._noise_calls += 1
        if self.config.noise_gain <= 0 or (self._noise_sets >= 100 and self._noise_calls % 10):
            return                       # settled: every 10th set is enough (deterministic)
        n = tri.num_views
        ok = (n >= self._noise_views) & (tri.error < np.inf)        # finite (NaN: False)
        count = int(np.count_nonzero(ok))
        if count < 5:
            return
        # DLT from n views leaves 2n - 3 of 2n degrees of freedom in the residuals; the median
        # of a 2D Gaussian error's length is 1.177 sigma.
        k = n[ok]
        e = tri.error[ok] * np.sqrt(2 * k / (2 * k - 3))
        sigma = float(np.partition(e, count // 2)[count // 2]) / 1.177
        self._noise_sets += 1
        if self._noise_sets == 1:
            self._noise_est = sigma
        else:
            self._noise_est += (sigma - self._noise_est) / min(self._noise_sets, 200)

    def measurement_variance(self, tri: Triangulation) -> np.ndarray:
        """
        Return the ``[K, J]`` per-axis variance [m^2] of triangulated joints (NaN if none).

        noise^2 * mean depth^2 / views (``noise_norm``, normalised units): a joint far from
        its cameras or seen by few of them is uncertain.
        """
        if not len(tri.joints):
            return np.zeros(tri.joints.shape[:2])
        # depth of each candidate's centre in each camera: the joints of a person are at
        # about the same distance from a camera, compared with the distance itself
        centre = centroid(tri.joints)                                       # [K, 3]
        depth = centre @ self._depth_rows[:, :3].T + self._depth_rows[:, 3]  # [K, C]
        n = tri.num_views
        with np.errstate(invalid='ignore', divide='ignore'):
            mean_depth = (tri.used * depth.T[:, :, None]).sum(axis=0) / n   # [K, J]
            var = self.noise_norm ** 2 * mean_depth * mean_depth / n
        return np.where(np.isfinite(tri.joints[..., 0]), np.maximum(var, _MIN_VARIANCE), np.nan)

    @property
    def last_info(self) -> Dict[str, float]:
        """Figures of the last step: counts, swaps, merges, median reprojection error (px)."""
        info = dict(self._info)
        if self._info_tri is not None:
            err = self._info_tri.error_px[np.isfinite(self._info_tri.error_px)]
            info['reprojection_error_px'] = float(np.median(err)) if err.size else float('nan')
        return info

    def cameras_in_view(self, poses: np.ndarray, per_camera: bool = False) -> np.ndarray:
        """
        Count, per pose ``[K, J, 3]``, the cameras whose image contains its joint centroid.

        ``per_camera``: return the ``[K, C]`` mask instead of the count.
        """
        centre = centroid(poses)                                            # [K, 3]
        cam = centre[:, None, None, :] @ self._projections[:, :, :3].transpose(0, 2, 1)
        cam = cam[:, :, 0] + self._projections[:, :, 3]                    # [K, C, 3]
        with np.errstate(invalid='ignore', divide='ignore'):
            x, y = cam[..., 0] / cam[..., 2], cam[..., 1] / cam[..., 2]
            b = self._bounds
            inside = (cam[..., 2] > 0) & (x >= b[:, 0]) & (x <= b[:, 1]) & (y >= b[:, 2]) \
                & (y <= b[:, 3])
        return inside if per_camera else inside.sum(axis=1)

    # ------------------------------------------------------------------ reconstruction
    def _warn(self, key: str, message: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            _LOG.warning('Fusion: %s', message)

    def _prepare(self, views: Mapping[str, np.ndarray]
                 ) -> Tuple[np.ndarray, np.ndarray, Tuple[int, ...], np.ndarray]:
        """
        Validate the views and normalise all keypoints at once.

        Returns ``x [N + 1, J, 3]`` homogeneous normalised points (NaN = missing) of the usable
        poses of all cameras in rig order, their confidences ``[N + 1, J]``, the ``offsets``
        (C + 1 ints: camera c has rows ``offsets[c]:offsets[c + 1]``) and the index of each
        pose in its view ``[N]``. The extra last row is a missing pose (NaN, confidence 0):
        index -1 of a ``members`` table picks it, so camera-major gathers need no masking.
        """
        cfg = self.config
        num_j = self.layout.num_joints
        arrays, counts = [], []
        for name in views:
            if name not in self._index:
                self._warn('cam:' + str(name), f'view of unknown camera {name!r} ignored '
                           f'(rig cameras: {", ".join(self.camera_names)})')
        for name in self.camera_names:
            arr = views.get(name)
            n = 0
            if arr is not None:
                arr = np.asarray(arr, dtype=float)
                if arr.ndim == 3 and arr.shape[1:] == (num_j, 3):
                    n = len(arr)
                elif arr.size:
                    self._warn(f'shape:{name}:{arr.shape}',
                               f'view of camera {name!r} has shape {arr.shape}, expected '
                               f'[P, {num_j}, 3] for layout {self.layout.name!r}: ignored')
            if n:
                arrays.append(arr)
            counts.append(n)
        if not arrays:
            return (np.full((1, num_j, 3), np.nan), np.zeros((1, num_j)), (0,) * (len(counts) + 1),
                    np.zeros(0, dtype=int))
        a = np.concatenate(arrays, axis=0) if len(arrays) > 1 else arrays[0]
        finite = np.isfinite(a)             # (three ands beat a last-axis all() of three)
        vis = finite[..., 0] & finite[..., 1] & finite[..., 2] \
            & (a[..., 2] >= cfg.min_joint_confidence)
        keep = vis.sum(axis=1) >= cfg.min_pose_joints
        offsets, cam_of, source = _stacking(tuple(counts))
        if not keep.all():
            a, vis, cam_of, source = a[keep], vis[keep], cam_of[keep], source[keep]
            counts = np.bincount(cam_of, minlength=len(counts)).tolist()
            offsets = tuple(accumulate(counts, initial=0))
        num_n = offsets[-1]
        k = self._k.take(cam_of, axis=0)[:, None, :]                       # [N, 1, 5]
        y = (a[..., 1] - k[..., 4]) / k[..., 3]
        x = np.empty((num_n + 1, num_j, 3))
        x[:num_n, :, 0] = (a[..., 0] - k[..., 2] - k[..., 1] * y) / k[..., 0]
        x[:num_n, :, 1] = y
        x[:num_n, :, 2] = 1.0
        for c, n in enumerate(counts):
            if n and self._distorted[c]:
                lo, hi = offsets[c], offsets[c + 1]
                x[lo:hi, :, :2] = self.cameras[c].undistort(a[lo:hi, :, :2])
        x[:num_n][~vis] = np.nan
        x[num_n] = np.nan
        conf = np.zeros((num_n + 1, num_j))
        conf[:num_n] = np.where(vis, np.minimum(np.maximum(a[..., 2], 0.0), 1.0), 0.0)
        return x, conf, offsets, source

    def _reconstruct(self, views: Mapping[str, np.ndarray]):
        """Associate, triangulate and clean up; return (Triangulation, members [K, C])."""
        cfg = self.config
        x, conf, offsets, source = self._prepare(views)
        num_n = offsets[-1]
        members = associate_stacked(x[:num_n], offsets, self._essentials,
                                    threshold=cfg.epipolar_threshold_norm,
                                    min_joints=cfg.min_shared_joints,
                                    max_reference_views=cfg.max_reference_views,
                                    min_views=cfg.min_views,
                                    norm_coefficients=self._norm_coef,
                                    order=self._order)
        info = {'poses_2d': num_n,
                'views_with_poses': sum(hi > lo for lo, hi in zip(offsets, offsets[1:])),
                'candidates': len(members)}
        tri, members, swaps = self._triangulate(x, conf, members)
        merged = 0
        if len(members) > 1 and cfg.merge_distance_m > 0:
            members, merged = self._merge(tri, members)
            if merged:
                tri, members, swaps = self._triangulate(x, conf, members)
        info.update(swapped_pairs=swaps, merged=merged, poses_3d=len(members))
        self.last_members = np.where(members >= 0, source.take(members), -1)
        self._x, self._offsets = x, offsets
        self._info, self._info_tri = info, tri
        return tri, members

    def _triangulate(self, x: np.ndarray, conf: np.ndarray, members: np.ndarray):
        """Triangulate candidates, fix swaps, check bones, drop thin candidates."""
        cfg = self.config
        g = members.T                                    # [C, K]; -1 picks the missing pose
        xg = x.take(g, axis=0)
        u, v, w = xg[..., 0], xg[..., 1], conf.take(g, axis=0)             # [C, K, J]
        tri = triangulate_robust(u, v, w, self._projections, self._focal,
                                 cfg.reprojection_gate_norm, cfg.min_views, self._basis)
        swaps = 0
        if cfg.swap_check and len(self._flip_pairs) and len(members):
            # A swapped view disagrees with the triangulation on a left or right joint; only
            # such (view, candidate, pair) triples are tested (in 2D, where the swap cannot
            # contaminate the test). view_error is finite or inf (not observed), never NaN.
            err = tri.view_error
            worse = np.maximum(err.take(self._flip_pairs[:, 0], axis=2),
                               err.take(self._flip_pairs[:, 1], axis=2))
            suspect = (worse > 0.3 * cfg.reprojection_gate_norm) & (worse < np.inf)
            if suspect.any():
                sw = swapped_views(u, v, w, self._essentials, self._flip_pairs, cfg.swap_ratio,
                                   ref_cams=self._reference_views(members),
                                   suspects=np.nonzero(suspect))
                if sw.any():
                    swaps = int(sw.sum())
                    u, v, w = swap_pairs(u, v, w, sw, self._flip_pairs)
                    tri = triangulate_robust(u, v, w, self._projections, self._focal,
                                             cfg.reprojection_gate_norm, cfg.min_views,
                                             self._basis)
        if cfg.bone_check and len(members):
            bad = bone_outliers(tri.joints, self._bones, self._bone_lo, self._bone_hi,
                                tri.error)
            if bad.any():
                _reject(tri, bad)
        keep = np.isfinite(tri.joints[..., 0]).sum(axis=1) >= cfg.min_candidate_joints
        if not keep.all():
            tri = _subset(tri, keep)
            members = members[keep]
        return tri, members, swaps

    def _reference_views(self, members: np.ndarray) -> np.ndarray:
        """Return ``[R, K]`` cameras: each candidate's first views in association order."""
        width = min(len(self._order), self.config.max_reference_views + 1)
        order = self._order.tolist()
        refs = []
        for row in members.tolist():                    # a few short rows: plain Python
            first = [c for c in order if row[c] >= 0][:width]
            refs.append(first + [-1] * (width - len(first)))
        return np.array(refs, dtype=int).reshape(-1, width).T

    def _merge(self, tri: Triangulation, members: np.ndarray):
        """Merge candidates closer than merge_distance_m seen by disjoint cameras; else NMS."""
        cfg = self.config
        centre = centroid(tri.joints)                 # cheap first: centres far apart
        d = centre[:, None] - centre[None]
        with np.errstate(invalid='ignore'):
            near = ((d * d).sum(axis=-1) < (cfg.merge_distance_m + _CENTRE_MARGIN_M) ** 2) \
                & _upper_triangle(len(centre))
        if not near.any():
            return members, 0
        dist = median_joint_distance(tri.joints, tri.joints, cfg.min_shared_joints)
        close = (dist < cfg.merge_distance_m) & near
        if not close.any():
            return members, 0
        ii, jj = np.nonzero(close)
        order = np.argsort(dist[ii, jj], kind='stable')
        alive = np.ones(len(members), dtype=bool)
        members = members.copy()
        strength = tri.num_views.sum(axis=1)
        merged = 0
        for i, j in zip(ii[order].tolist(), jj[order].tolist()):
            if not (alive[i] and alive[j]):
                continue
            a, b = members[i] >= 0, members[j] >= 0
            if not (a & b).any():
                members[i] = np.where(a, members[i], members[j])
                alive[j] = False
            elif strength[i] >= strength[j]:
                alive[j] = False
            else:
                alive[i] = False
            merged += 1
        return members[alive], merged

    # ------------------------------------------------------------------ output
    def _outputs(self, upd, tri: Triangulation, members: np.ndarray, variance: np.ndarray,
                 stamp: float, rays: Optional['_Rays'] = None) -> List[Track]:
        """Build the Track of every live track (vectorised over tracks)."""
        cfg = self.config
        det, previous, kal = upd.detection, upd.previous, upd.filtered
        tr: Tracks = self.tracker.tracks
        num_t, num_j = len(tr), self.layout.num_joints
        seen = det >= 0
        if seen.all():
            z, conf_obs = tri.joints.take(det, axis=0), tri.confidence.take(det, axis=0)
            num_views, err = tri.num_views.take(det, axis=0), tri.error_px.take(det, axis=0)
            r = variance.take(det, axis=0)
        else:                            # row K of the padded arrays is "not observed"
            z = np.concatenate((tri.joints, np.full((1, num_j, 3), np.nan))).take(det, axis=0)
            conf_obs = np.concatenate((tri.confidence, np.zeros((1, num_j)))).take(det, axis=0)
            num_views = np.concatenate((tri.num_views, np.zeros((1, num_j), int))
                                       ).take(det, axis=0)
            err = np.concatenate((tri.error_px, np.full((1, num_j), np.nan))).take(det, axis=0)
            r = np.concatenate((variance, np.full((1, num_j), np.nan))).take(det, axis=0)
        accepted = kal.accepted
        if not accepted.all():           # a rejected observation is not an observation
            z = np.where(accepted[..., None], z, np.nan)
            r = np.where(accepted, r, np.nan)
            num_views = np.where(accepted, num_views, 0)
            err = np.where(accepted, err, np.nan)
        only = None
        if rays is not None:             # joints only single views updated: their rays
            only = rays.accepted & ~np.isfinite(r)
            z = np.where(only[..., None], rays.point, z)
            r = np.where(only, rays.variance, r)
            num_views = num_views + rays.views
        observed = accepted
        if observed.all():
            conf_last = conf_obs
        else:
            conf_prev = np.where((previous >= 0)[:, None],
                                 self._confidence[np.maximum(previous, 0)]
                                 if len(self._confidence) else 0.0, 0.0)
            conf_last = np.where(observed, conf_obs, conf_prev)
        self._confidence = conf_last
        state, joint_var = kal.state, kal.variance
        if only is not None and only.any():
            # a ray leaves the depth open: as far as the person may have walked along it
            # since the last 3D match (a third of it per axis; the filter's isotropic
            # variance only knows the two axes across the ray)
            drift = cfg.tracking_gate_growth_mps * (stamp - tr.last_matched)
            joint_var = np.where(only, joint_var + (drift * drift / 3)[:, None], joint_var)
        if cfg.smoothing == 'causal':
            joints = kal.joints
        else:                            # accepted triangulations, held joints in gaps
            joints = np.where(observed[..., None], z, kal.joints)
            joint_var = np.where(observed, r, joint_var)
        missing = state == _MISSING
        confidence = np.where(missing, 0.0, np.where(state == _PREDICTED, 0.5, 1.0) * conf_last)
        velocity = tr.velocity
        cov = np.full((num_t, 3, 3), np.nan)
        source = np.full(num_t, int(PositionSource.HIPS), dtype=np.uint8)
        if self._root is None:
            position = np.full((num_t, 3), np.nan)
        else:
            # mean of the two root joints, written out (a two-element np.mean costs more)
            left, right = self._root
            position = (joints[:, left] + joints[:, right]) / 2
            root_var = (joint_var[:, left] + joint_var[:, right]) / 4
            no_hips = ~np.isfinite(position[:, 0])
            if no_hips.any():            # never a silent origin: the body's centre instead
                position, root_var = position.copy(), root_var.copy()
                body = centroid(np.where(np.isfinite(joints[no_hips]), joints[no_hips],
                                         tr.pose[no_hips]))
                position[no_hips] = body
                known = ~missing[no_hips] & np.isfinite(joint_var[no_hips])
                spread = np.where(known, joint_var[no_hips], 0.0).sum(axis=1) \
                    / np.maximum(known.sum(axis=1), 1)
                root_var[no_hips] = spread + _BODY_ROOT_VARIANCE
                source[no_hips] = np.where(np.isfinite(body[:, 0]), int(PositionSource.BODY),
                                           int(PositionSource.NONE))
            cov = root_var[:, None, None] * np.eye(3)
            filt = self.tracker.filter
            v = filt.v
            root_ok = (filt.count[:, left] >= 2) & (filt.count[:, right] >= 2) \
                & ~(missing[:, left] | missing[:, right])
            velocity = np.where(root_ok[:, None], (v[:, left] + v[:, right]) / 2, velocity)
        score = confidence.sum(axis=1) / num_j if num_j else np.zeros(num_t)     # = mean
        if cfg.max_coast_s > 0:
            fade = 1.0 - (stamp - tr.last_observed) / cfg.max_coast_s
            score = score * np.minimum(np.maximum(fade, 0.0), 1.0)
        num_views = num_views.astype(np.uint8)
        # per-track Python values in one conversion each (numpy scalars are slow one by one)
        names = self.camera_names
        seen_by = (members >= 0).tolist()
        view_sets = [tuple(compress(names, seen_by[d])) if d >= 0 else () for d in det.tolist()]
        if rays is not None and rays.cameras.any():
            both = rays.cameras.copy()
            has = det >= 0
            both[has] |= members[det[has]] >= 0
            view_sets = [tuple(compress(names, row)) for row in both.tolist()]
        sources = source.tolist()
        ids, states, hits, missed = (tr.ids.tolist(), tr.state.tolist(), tr.hits.tolist(),
                                     tr.missed.tolist())
        first_seen, last_observed, score = (tr.first_seen.tolist(), tr.last_observed.tolist(),
                                            score.tolist())
        first_ns, last_ns = tr.first_seen_ns.tolist(), tr.last_observed_ns.tolist()
        out = [Track(track_id=ids[i], state=_TRACK_STATES[states[i]], joints=joints[i],
                     confidence=confidence[i], joint_state=state[i], num_views=num_views[i],
                     reprojection_error=err[i], position=position[i], velocity=velocity[i],
                     first_seen=first_seen[i], last_observed=last_observed[i], age=hits[i],
                     missed=missed[i], score=score[i], source_cameras=view_sets[i],
                     joint_variance=joint_var[i], position_covariance=cov[i],
                     measurement=z[i], measurement_variance=r[i], first_seen_ns=first_ns[i],
                     last_observed_ns=last_ns[i], position_source=_SOURCES[sources[i]])
               for i in range(num_t)]
        out.sort(key=lambda t: t.track_id)
        return out

    def _tombstones(self, dead: Tracks) -> List[Track]:
        num_j = self.layout.num_joints
        out = []
        for i in range(len(dead)):
            position = np.full(3, np.nan)
            if self._root is not None and np.isfinite(dead.pose[i, list(self._root)]).all():
                position = dead.pose[i, list(self._root)].mean(axis=0)
            out.append(Track(track_id=int(dead.ids[i]), state=TrackState.DELETED,
                             joints=np.full((num_j, 3), np.nan), confidence=np.zeros(num_j),
                             joint_state=np.zeros(num_j, dtype=np.uint8),
                             num_views=np.zeros(num_j, dtype=np.uint8),
                             reprojection_error=np.full(num_j, np.nan), position=position,
                             velocity=np.full(3, np.nan),
                             first_seen=float(dead.first_seen[i]),
                             last_observed=float(dead.last_observed[i]),
                             first_seen_ns=int(dead.first_seen_ns[i]),
                             last_observed_ns=int(dead.last_observed_ns[i]),
                             age=int(dead.hits[i]), missed=int(dead.missed[i]), score=0.0,
                             source_cameras=()))
        return out


@dataclass
class _Rays:
    """Single-view updates of one step, per live track (see ``Fusion._update_from_views``)."""

    accepted: np.ndarray    # [T, J] a view updated the joint
    point: np.ndarray       # [T, J, 3] the first accepted ray's point nearest the prediction
    variance: np.ndarray    # [T, J] its variance across the ray [m^2]
    views: np.ndarray       # [T, J] views that updated the joint
    cameras: np.ndarray     # [T, C] cameras whose pose went to the track (member or single)


def _spread_ratio(proj: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """
    Return ``[N, P]`` size ratios of 2D poses ``[P, J, 2]`` (or ``[N, P, J, 2]``) to ``[N, J, 2]``.

    The size is the RMS distance of the joints both have from their mean, so a pose whose
    legs are hidden is compared with the projection's upper body only. NaN with < 2 shared.
    """
    det = poses if poses.ndim == 4 else np.broadcast_to(poses[None], (len(proj),) + poses.shape)
    ref = np.broadcast_to(proj[:, None], det.shape)
    ok = np.isfinite(det[..., 0]) & np.isfinite(ref[..., 0])             # [N, P, J]
    n = ok.sum(axis=-1)[..., None]
    with np.errstate(invalid='ignore', divide='ignore'):
        sizes = []
        for pts in (det, ref):
            pts = np.where(ok[..., None], pts, 0.0)
            centred = pts - pts.sum(axis=-2)[..., None, :] / n[..., None]
            sizes.append(np.sqrt((np.where(ok[..., None], centred, 0.0) ** 2).sum(axis=(-1, -2))
                                 / n[..., 0]))
        return np.where(n[..., 0] >= 2, sizes[0] / sizes[1], np.nan)


def _image_cost(proj: np.ndarray, poses: np.ndarray, min_joints: int) -> np.ndarray:
    """Return ``[N, P]`` mean distances of projected ``[N, J, 2]`` and detected ``[P, J, 2]``."""
    d = proj[:, None] - poses[None]
    dist = np.sqrt((d * d).sum(axis=-1))                              # [N, P, J], NaN: missing
    ok = np.isfinite(dist)
    n = ok.sum(axis=-1)
    mean = np.where(ok, dist, 0.0).sum(axis=-1) / np.maximum(n, 1)
    return np.where(n >= min_joints, mean, np.inf)


@functools.lru_cache(maxsize=256)
def _stacking(counts: Tuple[int, ...]) -> Tuple[Tuple[int, ...], np.ndarray, np.ndarray]:
    """
    Return ``(offsets, camera, index)`` of poses stacked from views with ``counts`` poses.

    Offsets are C + 1 ints; ``camera [N]`` and ``index [N]`` (in its view) are read-only.
    Cached: the same few counts come back frame after frame.
    """
    offsets = tuple(accumulate(counts, initial=0))
    camera = np.repeat(np.arange(len(counts)), counts)
    index = np.arange(offsets[-1]) - np.repeat(offsets[:-1], counts)
    camera.setflags(write=False)
    index.setflags(write=False)
    return offsets, camera, index


@functools.lru_cache(maxsize=None)
def _upper_triangle(size: int) -> np.ndarray:
    """Return the read-only ``[size, size]`` mask of pairs ``i < j`` (np.triu is slow)."""
    mask = np.triu(np.ones((size, size), dtype=bool), 1)
    mask.setflags(write=False)
    return mask


def _reject(tri: Triangulation, bad: np.ndarray) -> None:
    """Mark joints ``bad [K, J]`` of ``tri`` as not triangulated (in place)."""
    tri.joints[bad] = np.nan
    tri.confidence[bad] = 0.0
    tri.num_views[bad] = 0
    tri.error[bad] = np.nan
    tri.error_px[bad] = np.nan
    tri.used &= ~bad


def _subset(tri: Triangulation, keep: np.ndarray) -> Triangulation:
    """Return the candidates ``keep`` of ``tri``."""
    return Triangulation(joints=tri.joints[keep], confidence=tri.confidence[keep],
                         num_views=tri.num_views[keep], error=tri.error[keep],
                         error_px=tri.error_px[keep], used=tri.used[:, keep],
                         gated=tri.gated[keep], worst_error=tri.worst_error[keep],
                         view_error=tri.view_error[:, keep])


def _normalised_bounds(cam: Camera, samples: int = 9) -> np.ndarray:
    """Return ``(x_min, x_max, y_min, y_max)`` of a box inside the undistorted image."""
    s = np.linspace(0.0, 1.0, samples)
    w, h = cam.width - 1.0, cam.height - 1.0
    edges = [np.stack([np.zeros_like(s), s * h], 1), np.stack([np.full_like(s, w), s * h], 1),
             np.stack([s * w, np.zeros_like(s)], 1), np.stack([s * w, np.full_like(s, h)], 1)]
    left, right, top, bottom = (cam.undistort(e) for e in edges)
    box = np.array([np.nanmax(left[:, 0]), np.nanmin(right[:, 0]),
                    np.nanmax(top[:, 1]), np.nanmin(bottom[:, 1])])
    return np.nan_to_num(box, nan=0.0)
