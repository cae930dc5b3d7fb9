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

One ``Fusion.step`` per synchronised set of views runs the whole of Tanke & Gall's method, one
stage after the other over the set's ``SetRecord`` (``core.fusion.record``): reconstruct
candidate 3D poses (``core.fusion.reconstruction``: normalise, associate, triangulate, undo
swaps, check bones, merge candidates), estimate the 2D noise and each joint's measurement
variance (``core.fusion.noise``), track (``core.tracking.tracker``, per-joint Kalman filters in
``core.tracking.smoothing``), fold in the views no triangulation used (``core.fusion.views``),
assemble the tracks (``core.fusion.assembly``) and count duplicate tracks
(``core.fusion.duplicates``). The live node and the offline command both call it, so their
results agree frame for frame.

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
import logging
from typing import Dict, List, Mapping, Optional, Set, Union

from mv3dpose_ros.core.fusion.assembly import TrackAssembly
from mv3dpose_ros.core.fusion.config import FusionConfig, SMOOTHING_MODES
from mv3dpose_ros.core.fusion.duplicates import DuplicateTracks, near_a_track
from mv3dpose_ros.core.fusion.noise import NoiseModel
from mv3dpose_ros.core.fusion.reconstruction import Reconstruction
from mv3dpose_ros.core.fusion.record import SetRecord
from mv3dpose_ros.core.fusion.rig import Rig
from mv3dpose_ros.core.fusion.views import (SAME_INSTANT_S, VIEW_PAIR_S, VIEW_SCALE_RATIO,
                                            ViewUpdates)
from mv3dpose_ros.core.geometry.camera import Camera
from mv3dpose_ros.core.geometry.triangulation import Triangulation
from mv3dpose_ros.core.skeleton import get_layout, Layout
from mv3dpose_ros.core.tracking.tracker import filled, Tracker, TrackUpdate
from mv3dpose_ros.core.types import Stamp, Track
import numpy as np

__all__ = ['Fusion', 'FusionConfig', 'SAME_INSTANT_S', 'SMOOTHING_MODES', 'VIEW_PAIR_S',
           'VIEW_SCALE_RATIO']

_LOG = logging.getLogger(__name__)


class Fusion:
    """Fuse synchronised 2D poses of a calibrated rig into tracked 3D skeletons."""

    def __init__(self, cameras: Mapping[str, Camera], layout, config: Optional[FusionConfig] = None
                 ) -> None:
        """Precompute the rig geometry (essential matrices once per camera pair)."""
        self.config = config if config is not None else FusionConfig()
        self.config.validate()
        cfg = self.config
        self._rig = Rig.of(cameras)
        self.layout: Layout = get_layout(layout)
        self.camera_names = self._rig.names
        self.cameras = self._rig.cameras
        num_c, num_j = len(self._rig), self.layout.num_joints
        self._birth_views = max(2, min(cfg.min_birth_cameras_in_view, num_c - 1))
        self._strong_views = min(3, num_c)
        self._confirm_joints = cfg.confirm_at_birth_ratio * num_j
        self.tracker = Tracker(num_j, cfg.tracker_config(num_c), num_cameras=num_c)
        #: Counters since construction: tracks updated by single views in a step
        #: ('view_updates'), late views used ('late_views_used'), tracks found again after
        #: they stopped being published ('recovered'), duplicates merged ('merged_tracks').
        self.counts: Counter = Counter()
        self._warned: Set[str] = set()
        self._noise = NoiseModel(cfg, self._rig.depth_rows)
        self._reconstruction = Reconstruction(self._rig, self.layout, cfg, self._warn)
        self._views = ViewUpdates(self._rig, self.layout, cfg, self.tracker, self._noise,
                                  self.counts)
        self._duplicates = DuplicateTracks(cfg, self.tracker, self.counts)
        self._assembly = TrackAssembly(self.layout, cfg, self.tracker, self.camera_names)
        self._last_stamp: Optional[float] = None
        self._last: Optional[SetRecord] = None          # the record of the last step

    # ------------------------------------------------------------------ public API
    def replace_camera(self, camera: Camera) -> None:
        """Use ``camera`` (a new pose of a camera of the rig, same name) from the next step on."""
        self._rig.replace_camera(camera)

    def reset(self) -> List[Track]:
        """Clear all tracks and filters; return their DELETED tombstones (ids keep counting)."""
        dropped = self._assembly.tombstones(self.tracker.reset())
        self._duplicates.clear()
        self._last_stamp = None
        return dropped

    def step(self, views: Mapping[str, np.ndarray], stamp: Union[float, Stamp],
             stamp_ns: Optional[int] = None) -> List[Track]:
        """
        Fuse one synchronised set of views taken at ``stamp`` (seconds or a ``Stamp``) into tracks.

        ``views`` maps camera name -> ``[P, J, 3]`` raw-pixel 2D poses (x, y, confidence;
        confidence 0 = missing joint) in the layout's joint order; cameras may be absent and
        P may be 0. Returns the live tracks (TENTATIVE, CONFIRMED, COASTING) in id order, then
        the tracks deleted in this step, once, as DELETED tombstones. Bad views (unknown
        camera, wrong shape) are skipped with a logged warning naming them. A stamp earlier
        than the previous one resets the tracks first (their tombstones come with this step).
        ``stamp_ns`` is the same stamp in integer nanoseconds (see ``Stamp.of``); the tracks'
        ``first_seen_ns`` / ``last_observed_ns`` are copies of it, exactly.
        """
        at = Stamp.of(stamp, stamp_ns)
        tombs = self._check_time(at)
        s = self._last = self._reconstruction.run(views, at)
        self._noise.fold(s.tri)
        s.variance = self._noise.variance(s.tri, s.centres)
        merged = self._duplicates.merge()
        tr = self.tracker.tracks
        lost = tr.ids[at.s - tr.last_observed > self.config.publish_coast_s + 1e-9]
        s.update = self.tracker.update(s.tri.joints, at, lambda rows: self._can_birth(s, rows),
                                       s.variance, lambda rows: self._strong(s, rows),
                                       cameras=s.members >= 0, sparse=s.sparse)
        s.track_members = _track_members(s.members, s.update)
        s.track_seen = s.track_members >= 0
        if self.config.view_updates:
            self._views.note(s)
            if len(self.tracker.tracks):
                s.rays = self._views.update_set(s)
        if len(lost):
            tr = self.tracker.tracks
            back = tr.ids[tr.last_observed == at.s]
            self.counts['recovered'] += len(set(back.tolist()).intersection(lost.tolist()))
        out = self._assembly.tracks(s)
        self._duplicates.count(s)
        if merged is not None:
            tombs += self._assembly.tombstones(merged)
        return out + tombs + self._assembly.tombstones(s.update.deleted)

    def update_view(self, camera: str, poses: np.ndarray, stamp: Union[float, Stamp],
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
        at = Stamp.of(stamp, stamp_ns)
        index = self._rig.index
        if not self.config.view_updates or not len(self.tracker.tracks) or camera not in index:
            if camera not in index:
                self._warn('cam:' + str(camera), f'view of unknown camera {camera!r} ignored '
                           f'(rig cameras: {", ".join(self.camera_names)})')
            return 0
        if self._last_stamp is not None and at.s < self._last_stamp - self.config.max_coast_s:
            return 0                     # older than anything the tracks still hold
        points = self._reconstruction.points({camera: poses})
        return self._views.update_late(index[camera], points, at)

    @property
    def max_coast_s(self) -> float:
        """Return how long [s] the tracker keeps a track unobserved before it is DELETED."""
        return self.tracker.config.max_coast_s

    @max_coast_s.setter
    def max_coast_s(self, seconds: float) -> None:
        """
        Let tracks coast ``seconds`` (a live rig whose sets come slowly keeps them longer).

        ``config.max_coast_s`` stays the configured value: the score still fades over it and
        late views older than it are still ignored.
        """
        self.tracker.config.max_coast_s = float(seconds)

    @property
    def noise_norm(self) -> float:
        """Return the 2D noise per view (normalised units) behind the measurement variance."""
        return self._noise.norm

    def measurement_variance(self, tri: Triangulation) -> np.ndarray:
        """Return the ``[K, J]`` per-axis variance [m^2] of triangulated joints (NaN if none)."""
        return self._noise.variance(tri)

    def cameras_in_view(self, poses: np.ndarray, per_camera: bool = False) -> np.ndarray:
        """
        Count, per pose ``[K, J, 3]``, the cameras whose image contains its joint centroid.

        ``per_camera``: return the ``[K, C]`` mask instead of the count.
        """
        return self._rig.cameras_in_view(poses, per_camera)

    @property
    def last_poses(self) -> np.ndarray:
        """Return the 3D poses ``[K, J, 3]`` triangulated in the last step, before tracking."""
        if self._last is None:
            return np.empty((0, self.layout.num_joints, 3))
        return self._last.tri.joints

    @property
    def last_members(self) -> np.ndarray:
        """
        Return ``[K, C]``: the index of the input 2D pose behind each of ``last_poses``.

        Per camera (rig order), the index in ``views[camera]``; -1 where a camera did not
        contribute.
        """
        if self._last is None:
            return np.zeros((0, len(self.cameras)), dtype=int)
        members = self._last.members
        return np.where(members >= 0, self._last.points.source.take(members), -1)

    @property
    def last_info(self) -> Dict[str, float]:
        """Figures of the last step: counts, swaps, merges, median reprojection error (px)."""
        if self._last is None:
            return {}
        info = dict(self._last.info)
        err = self._last.tri.error_px[np.isfinite(self._last.tri.error_px)]
        info['reprojection_error_px'] = float(np.median(err)) if err.size else float('nan')
        return info

    # ------------------------------------------------------------------ the step's parts
    def _check_time(self, at: Stamp) -> List[Track]:
        """Reset the tracks when the stamp went back; return their tombstones."""
        tombs: List[Track] = []
        if self._last_stamp is not None and at.s < self._last_stamp:
            self._warn('time', f'stamp went back from {self._last_stamp:.6f} s to {at.s:.6f} s:'
                       ' tracks reset (warned once)')
            tombs = self.reset()
        self._last_stamp = at.s
        return tombs

    def _can_birth(self, s: SetRecord, rows: np.ndarray) -> np.ndarray:
        """
        Tell which candidates ``rows`` left unmatched may start a track.

        Inside the shared field of view, well supported by the cameras of this set that
        should see it (a camera whose message missed the set cannot have seen anyone), and
        no fragment of a tracked person (its views split from the rest by the association:
        a track of it would be a duplicate).
        """
        cfg = self.config
        joints = s.tri.joints
        inside = self._rig.cameras_in_view(joints[rows], per_camera=True)     # [N, C]
        views_ = (s.members[rows] >= 0).sum(axis=1)
        ok = (inside.sum(axis=1) >= self._birth_views) \
            & (views_ >= cfg.min_birth_view_ratio * (inside & s.present).sum(axis=1))
        if ok.any() and len(self.tracker.tracks):
            predicted = self.tracker.tracks.predicted(s.stamp.s, cfg.tracking_prediction,
                                                      self.tracker.config.max_predict_s)
            ok[ok] = ~near_a_track(joints[rows[ok]], predicted, cfg.merge_distance_m,
                                   cfg.min_shared_joints)
        return ok

    def _strong(self, s: SetRecord, rows: np.ndarray) -> np.ndarray:
        """Tell which new tracks ``rows`` are CONFIRMED at once: enough well-seen joints."""
        well_seen = (s.tri.num_views[rows] >= self._strong_views).sum(axis=1)
        return well_seen >= self._confirm_joints

    def _warn(self, key: str, message: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            _LOG.warning('Fusion: %s', message)


def _track_members(members: np.ndarray, update: TrackUpdate) -> np.ndarray:
    """Return ``[T, C]``: the members of the candidate each track took (-1: none)."""
    detection = update.detection
    if update.complete:
        return members.take(detection, axis=0)
    out = filled((len(detection), members.shape[1]), -1, int)
    has = detection >= 0
    if has.any():
        out[has] = members[detection[has]]
    return out
