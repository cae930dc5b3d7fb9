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
undistort every keypoint once, associate poses across views (``core.association``),
triangulate with a reprojection gate, undo single-view left/right swaps, reject implausible
bones, merge duplicate candidates (``core.triangulation``), track (``core.tracking``) and
smooth causally (``core.smoothing``). The live node and the offline command both call it, so
their results agree frame for frame.

Units: thresholds on image distances are in normalised image units (pixels / focal length;
0.02 = 20 px at f = 1000 px), 3D distances in metres, times in seconds (field names say so).
"""

from dataclasses import asdict, dataclass
import logging
from typing import Dict, List, Mapping, Optional, Set

from mv3dpose_ros.core.association import associate
from mv3dpose_ros.core.camera import Camera, essential_matrix
from mv3dpose_ros.core.skeleton import get_layout, Layout
from mv3dpose_ros.core.smoothing import CausalFilter
from mv3dpose_ros.core.tracking import (centroid, pose_distance, Tracker, TrackerConfig,
                                        TrackRecord)
from mv3dpose_ros.core.triangulation import (bone_length_limits, bone_outliers, swap_pairs,
                                             swapped_views, triangulate_robust, Triangulation)
from mv3dpose_ros.core.types import JointState, Track, TrackState
import numpy as np

_LOG = logging.getLogger(__name__)

SMOOTHING_MODES = ('causal', 'none')


@dataclass
class FusionConfig:
    """Parameters of ``Fusion`` (all defaulted; units in the names, ``_norm`` = px / focal)."""

    # 2D input
    min_joint_confidence: float = 0.1       # keypoints below this count as missing
    min_pose_joints: int = 4                # 2D poses with fewer visible joints are ignored
    # association (paper: theta)
    epipolar_threshold_norm: float = 0.02   # mean symmetric epipolar distance gate
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
    tracking_prediction: bool = True        # constant-velocity prediction of the root
    confirm_hits: int = 3                   # observations before a track is CONFIRMED
    max_coast_s: float = 1.0                # unobserved time before a track is DELETED
    min_birth_joints: int = 6               # triangulated joints to start a new track
    min_birth_cameras_in_view: int = 3      # cameras whose image must contain a new track's
    #                                         centroid (capped at cameras - 1): no tracks are
    #                                         started outside the rig's shared working volume
    # causal smoothing
    smoothing: str = 'causal'               # 'causal' (alpha-beta per joint) or 'none'
    smoothing_alpha: float = 0.6            # position gain per update (1 = no smoothing)
    smoothing_beta: float = 0.25            # velocity gain per update
    max_gap_s: float = 0.3                  # joints are predicted for at most this long
    smoothing_reset_m: float = 0.5          # jump that restarts a joint's filter

    def validate(self) -> None:
        """Raise ValueError naming the first out-of-range field."""
        positive = ('epipolar_threshold_norm', 'reprojection_gate_norm', 'tracking_gate_m',
                    'smoothing_alpha', 'smoothing_reset_m')
        non_negative = ('min_joint_confidence', 'swap_ratio', 'merge_distance_m',
                        'tracking_gate_growth_mps', 'max_coast_s', 'smoothing_beta',
                        'max_gap_s')
        at_least_one = ('min_pose_joints', 'min_shared_joints', 'max_reference_views',
                        'min_candidate_joints', 'confirm_hits', 'min_birth_joints',
                        'min_birth_cameras_in_view')
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
        if self.smoothing_alpha > 1 or self.smoothing_beta > 1:
            raise ValueError('FusionConfig.smoothing_alpha and smoothing_beta must be <= 1')
        if self.smoothing not in SMOOTHING_MODES:
            raise ValueError(f'FusionConfig.smoothing must be one of {SMOOTHING_MODES}, '
                             f'got {self.smoothing!r}')


class _Extra:
    """Per-track output state kept by ``Fusion`` in ``TrackRecord.extra``."""

    __slots__ = ('filter', 'confidence', 'cameras')

    def __init__(self, num_joints: int, filt: Optional[CausalFilter]) -> None:
        self.filter = filt
        self.confidence = np.zeros(num_joints)
        self.cameras: tuple = ()


class Fusion:
    """Fuse synchronised 2D poses of a calibrated rig into tracked 3D skeletons."""

    def __init__(self, cameras: Mapping[str, Camera], layout, config: Optional[FusionConfig] = None
                 ) -> None:
        """Precompute the rig geometry (essential matrices once per camera pair)."""
        self.config = config if config is not None else FusionConfig()
        self.config.validate()
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
        self._essentials = np.zeros((num_c, num_c, 3, 3))
        for a in range(num_c):
            for b in range(num_c):
                if a != b:
                    self._essentials[a, b] = essential_matrix(self.cameras[a], self.cameras[b])
        self._projections = np.stack([np.hstack([c.R, c.t[:, None]]) for c in self.cameras])
        self._focal = np.array([c.focal for c in self.cameras])
        self._bounds = np.array([_normalised_bounds(c) for c in self.cameras])   # [C, 4]
        self._birth_views = max(2, min(self.config.min_birth_cameras_in_view, num_c - 1))
        lay = self.layout
        self._bones = np.array(lay.bones, dtype=int).reshape(-1, 2)
        self._bone_lo, self._bone_hi = bone_length_limits(lay.joint_names, lay.bones)
        self._flip_pairs = np.array(lay.flip_pairs, dtype=int).reshape(-1, 2)
        try:
            self._root = np.array(lay.root_joints, dtype=int)
        except ValueError:
            self._root = None
        cfg = self.config
        self.tracker = Tracker(TrackerConfig(
            gate_m=cfg.tracking_gate_m, gate_growth_mps=cfg.tracking_gate_growth_mps,
            min_shared_joints=cfg.min_shared_joints, predict=cfg.tracking_prediction,
            confirm_hits=cfg.confirm_hits, max_coast_s=cfg.max_coast_s,
            min_birth_joints=cfg.min_birth_joints), root_joints=self._root)
        self._last_stamp: Optional[float] = None
        self._warned: Set[str] = set()
        #: 3D poses ``[K, J, 3]`` triangulated in the last step, before tracking.
        self.last_poses = np.empty((0, lay.num_joints, 3))
        #: Figures of the last step (counts, median reprojection error in px).
        self.last_info: Dict[str, float] = {}

    # ------------------------------------------------------------------ public API
    def reset(self) -> List[Track]:
        """Clear all tracks and filters; return their DELETED tombstones (ids keep counting)."""
        dropped = [self._tombstone(t) for t in self.tracker.reset()]
        self._last_stamp = None
        return dropped

    def step(self, views: Mapping[str, np.ndarray], stamp: float) -> List[Track]:
        """
        Fuse one synchronised set of views taken at ``stamp`` seconds into tracks.

        ``views`` maps camera name -> ``[P, J, 3]`` raw-pixel 2D poses (x, y, confidence;
        confidence 0 = missing joint) in the layout's joint order; cameras may be absent and
        P may be 0. Returns the live tracks (TENTATIVE, CONFIRMED, COASTING) sorted by id, then
        the tracks deleted in this step, once, as DELETED tombstones. Bad views (unknown
        camera, wrong shape) are skipped with a logged warning naming them.
        """
        stamp = float(stamp)
        out_tomb: List[Track] = []
        if self._last_stamp is not None and stamp < self._last_stamp:
            self._warn('time', f'stamp went back from {self._last_stamp:.6f} s to {stamp:.6f} s:'
                       ' tracks reset')
            out_tomb = self.reset()
        self._last_stamp = stamp
        tri, members = self._reconstruct(views)
        self.last_poses = tri.joints
        live, deleted = self.tracker.update(tri.joints, stamp,
                                            self.cameras_in_view(tri.joints) >= self._birth_views)
        out = [self._output(t, tri, members, stamp) for t in live]
        out.sort(key=lambda t: t.track_id)
        return out + out_tomb + [self._tombstone(t) for t in deleted]

    def cameras_in_view(self, poses: np.ndarray) -> np.ndarray:
        """Count, per pose ``[K, J, 3]``, the cameras whose image contains its joint centroid."""
        centre = centroid(poses)                                            # [K, 3]
        cam = np.einsum('cab,kb->kca', self._projections[:, :, :3], centre) \
            + self._projections[None, :, :, 3]
        with np.errstate(invalid='ignore', divide='ignore'):
            x, y = cam[..., 0] / cam[..., 2], cam[..., 1] / cam[..., 2]
            b = self._bounds
            inside = (cam[..., 2] > 0) & (x >= b[:, 0]) & (x <= b[:, 1]) & (y >= b[:, 2]) \
                & (y <= b[:, 3])
        return inside.sum(axis=1)

    # ------------------------------------------------------------------ reconstruction
    def _warn(self, key: str, message: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            _LOG.warning('Fusion: %s', message)

    def _prepare(self, views: Mapping[str, np.ndarray]):
        """Validate views, undistort all keypoints once; return per-camera arrays."""
        cfg = self.config
        num_j = self.layout.num_joints
        pts, vis, conf = [], [], []
        empty2, empty1 = np.empty((0, num_j, 2)), np.empty((0, num_j))
        for name in views:
            if name not in self._index:
                self._warn('cam:' + str(name), f'view of unknown camera {name!r} ignored '
                           f'(rig cameras: {", ".join(self.camera_names)})')
        for name, cam in zip(self.camera_names, self.cameras):
            arr = views.get(name)
            if arr is None:
                pts.append(empty2)
                vis.append(empty1.astype(bool))
                conf.append(empty1)
                continue
            arr = np.asarray(arr, dtype=float)
            if arr.size == 0:
                arr = arr.reshape(0, num_j, 3)
            if arr.ndim != 3 or arr.shape[1:] != (num_j, 3):
                self._warn(f'shape:{name}:{arr.shape}',
                           f'view of camera {name!r} has shape {arr.shape}, expected '
                           f'[P, {num_j}, 3] for layout {self.layout.name!r}: ignored')
                arr = arr[:0].reshape(0, num_j, 3) if arr.ndim else np.empty((0, num_j, 3))
            c = arr[..., 2]
            with np.errstate(invalid='ignore'):
                v = (c >= cfg.min_joint_confidence) & np.isfinite(arr).all(axis=-1)
            keep = v.sum(axis=1) >= cfg.min_pose_joints
            if not keep.all():
                arr, v, c = arr[keep], v[keep], c[keep]
            xy = np.where(v[..., None], arr[..., :2], np.nan)
            pts.append(cam.undistort(xy) if len(xy) else empty2)
            vis.append(v)
            conf.append(np.where(v, np.clip(c, 0.0, 1.0), 0.0))
        return pts, vis, conf

    def _reconstruct(self, views: Mapping[str, np.ndarray]):
        """Associate, triangulate and clean up; return (Triangulation, members [K, C])."""
        cfg = self.config
        pts, vis, conf = self._prepare(views)
        num_j = self.layout.num_joints
        counts = np.array([len(p) for p in pts])
        offsets = np.concatenate(([0], np.cumsum(counts)))
        info = {'poses_2d': int(offsets[-1]), 'views_with_poses': int((counts > 0).sum())}
        members = associate(pts, vis, self._essentials, threshold=cfg.epipolar_threshold_norm,
                            min_joints=cfg.min_shared_joints,
                            max_reference_views=cfg.max_reference_views,
                            min_views=cfg.min_views)
        x_all = np.concatenate(pts + [np.full((1, num_j, 2), np.nan)], axis=0)
        w_all = np.concatenate(conf + [np.zeros((1, num_j))], axis=0)
        gidx = np.where(members >= 0, members + offsets[:-1][None, :], offsets[-1])
        info['candidates'] = len(members)
        tri, members, gidx, swaps = self._triangulate(x_all, w_all, members, gidx)
        info['swapped_pairs'] = swaps
        merged = 0
        if len(members) > 1 and cfg.merge_distance_m > 0:
            members, gidx, merged = self._merge(tri, members, gidx)
            if merged:
                tri, members, gidx, swaps = self._triangulate(x_all, w_all, members, gidx)
        info['merged'] = merged
        ok = np.isfinite(tri.error_px)
        info['poses_3d'] = len(members)
        info['reprojection_error_px'] = float(np.median(tri.error_px[ok])) if ok.any() \
            else float('nan')
        self.last_info = info
        return tri, members

    def _triangulate(self, x_all, w_all, members, gidx):
        """Triangulate candidates, fix swaps, check bones, drop thin candidates."""
        cfg = self.config
        points, weights = x_all[gidx], w_all[gidx]
        gate = cfg.reprojection_gate_norm
        tri = triangulate_robust(points, weights, self._projections, self._focal, gate,
                                 cfg.min_views)
        swaps = 0
        if cfg.swap_check and len(members) and len(self._flip_pairs):
            sw = swapped_views(points, weights, tri, self._projections, self._flip_pairs, gate,
                               cfg.swap_ratio)
            if sw.any():
                swaps = int(sw.sum())
                points, weights = swap_pairs(points, weights, sw, self._flip_pairs)
                tri = triangulate_robust(points, weights, self._projections, self._focal, gate,
                                         cfg.min_views)
        if cfg.bone_check and len(members):
            bad = bone_outliers(tri.joints, self._bones, self._bone_lo, self._bone_hi,
                                tri.error)
            if bad.any():
                _reject(tri, bad)
        keep = np.isfinite(tri.joints).all(axis=-1).sum(axis=1) >= cfg.min_candidate_joints
        if not keep.all():
            tri = _subset(tri, keep)
            members, gidx = members[keep], gidx[keep]
        return tri, members, gidx, swaps

    def _merge(self, tri: Triangulation, members: np.ndarray, gidx: np.ndarray):
        """Merge candidates closer than merge_distance_m seen by disjoint cameras; else NMS."""
        cfg = self.config
        dist = pose_distance(tri.joints, tri.joints, cfg.min_shared_joints)
        iu = np.triu_indices(len(members), 1)
        close = dist[iu] < cfg.merge_distance_m
        if not close.any():
            return members, gidx, 0
        pairs = sorted(zip(dist[iu][close], iu[0][close], iu[1][close]))
        alive = np.ones(len(members), dtype=bool)
        members, gidx = members.copy(), gidx.copy()
        strength = tri.num_views.sum(axis=1)
        merged = 0
        for _, i, j in pairs:
            if not (alive[i] and alive[j]):
                continue
            a, b = members[i] >= 0, members[j] >= 0
            if not (a & b).any():
                members[i] = np.where(a, members[i], members[j])
                gidx[i] = np.where(a, gidx[i], gidx[j])
                alive[j] = False
            elif strength[i] >= strength[j]:
                alive[j] = False
            else:
                alive[i] = False
            merged += 1
        return members[alive], gidx[alive], merged

    # ------------------------------------------------------------------ output
    def _output(self, t: TrackRecord, tri: Triangulation, members: np.ndarray,
                stamp: float) -> Track:
        cfg = self.config
        num_j = self.layout.num_joints
        if t.extra is None:
            filt = None
            if cfg.smoothing == 'causal':
                filt = CausalFilter(num_j, cfg.smoothing_alpha, cfg.smoothing_beta,
                                    cfg.max_gap_s, cfg.smoothing_reset_m)
            t.extra = _Extra(num_j, filt)
        ex: _Extra = t.extra
        d = t.detection
        if d >= 0:
            z = tri.joints[d]
            seen = np.isfinite(z).all(axis=-1)
            ex.confidence = np.where(seen, tri.confidence[d], ex.confidence)
            num_views = tri.num_views[d].astype(np.uint8)
            err = np.where(seen, tri.error_px[d], np.nan)
            ex.cameras = tuple(self.camera_names[c] for c in np.nonzero(members[d] >= 0)[0])
        else:
            z = np.full((num_j, 3), np.nan)
            num_views = np.zeros(num_j, dtype=np.uint8)
            err = np.full(num_j, np.nan)
            ex.cameras = ()
        if ex.filter is not None:
            joints, state = ex.filter.update(z, stamp)
            velocity_j = ex.filter.v
        else:
            if d >= 0:
                joints = z.copy()
                state = np.where(seen, JointState.TRIANGULATED, JointState.MISSING)
            else:
                joints = t.predicted(stamp, cfg.tracking_prediction).copy()
                state = np.where(np.isfinite(joints).all(axis=-1), JointState.PREDICTED,
                                 JointState.MISSING)
            state = state.astype(np.uint8)
            velocity_j = None
        missing = state == JointState.MISSING
        joints[missing] = np.nan
        predicted = state == JointState.PREDICTED
        confidence = np.where(missing, 0.0, np.where(predicted, 0.5 * ex.confidence,
                                                     ex.confidence))
        position = np.full(3, np.nan)
        velocity = t.velocity.copy()
        if self._root is not None:
            r = joints[self._root]
            if np.isfinite(r).all():
                position = r.mean(axis=0)
                if velocity_j is not None and not missing[self._root].any():
                    velocity = velocity_j[self._root].mean(axis=0)
        score = float(confidence.mean()) if num_j else 0.0
        if d < 0 and cfg.max_coast_s > 0:
            score *= max(0.0, 1.0 - (stamp - t.last_observed) / cfg.max_coast_s)
        return Track(track_id=t.track_id, state=t.state, joints=joints,
                     confidence=confidence, joint_state=state, num_views=num_views,
                     reprojection_error=err, position=position, velocity=velocity,
                     first_seen=t.first_seen, last_observed=t.last_observed, age=t.hits,
                     missed=t.missed, score=score, source_cameras=ex.cameras)

    def _tombstone(self, t: TrackRecord) -> Track:
        num_j = self.layout.num_joints
        position = np.full(3, np.nan)
        if self._root is not None and np.isfinite(t.pose[self._root]).all():
            position = t.pose[self._root].mean(axis=0)
        return Track(track_id=t.track_id, state=TrackState.DELETED,
                     joints=np.full((num_j, 3), np.nan), confidence=np.zeros(num_j),
                     joint_state=np.zeros(num_j, dtype=np.uint8),
                     num_views=np.zeros(num_j, dtype=np.uint8),
                     reprojection_error=np.full(num_j, np.nan), position=position,
                     velocity=np.full(3, np.nan), first_seen=t.first_seen,
                     last_observed=t.last_observed, age=t.hits, missed=t.missed, score=0.0,
                     source_cameras=())


def _reject(tri: Triangulation, bad: np.ndarray) -> None:
    """Mark joints ``bad [K, J]`` of ``tri`` as not triangulated (in place)."""
    tri.joints[bad] = np.nan
    tri.confidence[bad] = 0.0
    tri.num_views[bad] = 0
    tri.error[bad] = np.nan
    tri.error_px[bad] = np.nan
    tri.used &= ~bad[:, None, :]


def _subset(tri: Triangulation, keep: np.ndarray) -> Triangulation:
    """Return the candidates ``keep`` of ``tri``."""
    return Triangulation(joints=tri.joints[keep], confidence=tri.confidence[keep],
                         num_views=tri.num_views[keep], error=tri.error[keep],
                         error_px=tri.error_px[keep], used=tri.used[keep])


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
