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
The output of a step: one ``Track`` per live track, and a DELETED tombstone per track gone.

Vectorised over tracks: joints (filtered, or the accepted raw triangulations with
``smoothing='none'``), their variance (a joint only single views updated adds the depth the
person may have walked along the ray since the last 3D match), the root (the hips' midpoint;
without a hip the body's centre, never a silent origin) with its covariance and velocity, the
score (mean joint confidence, faded over ``max_coast_s`` unobserved) and the cameras behind it.
"""

from itertools import compress
from operator import attrgetter
from typing import List, Optional, Tuple

from mv3dpose_ros.core.fusion.config import FusionConfig
from mv3dpose_ros.core.fusion.record import SetRecord
from mv3dpose_ros.core.skeleton import Layout
from mv3dpose_ros.core.tracking.tracker import centroid, filled, padded, Tracker, Tracks
from mv3dpose_ros.core.types import JointState, PositionSource, Track, TrackState
import numpy as np

#: Extra per-axis variance of a root taken from the body instead of the hips [m^2]: (15 cm)^2.
BODY_ROOT_VARIANCE = 0.15 ** 2

# Joint states as plain ints: comparing an array with an IntEnum member costs ~6x more.
_MISSING, _PREDICTED = int(JointState.MISSING), int(JointState.PREDICTED)
_TRACK_STATES = {int(s): s for s in TrackState}
_SOURCES = {int(s): s for s in PositionSource}
_BY_ID = attrgetter('track_id')
_EYE3 = np.eye(3)
_EYE3.setflags(write=False)


class TrackAssembly:
    """Build the ``Track`` outputs of a step from its record and the tracker's state."""

    def __init__(self, layout: Layout, config: FusionConfig, tracker: Tracker,
                 camera_names: Tuple[str, ...]) -> None:
        """Read ``tracker``'s tracks; ``camera_names`` in rig order name the source cameras."""
        self.layout, self.config, self.tracker = layout, config, tracker
        self.camera_names = camera_names
        try:
            self._root: Optional[Tuple[int, int]] = tuple(layout.root_joints)
        except ValueError:
            self._root = None

    def tracks(self, s: SetRecord) -> List[Track]:
        """Return the ``Track`` of every live track after set ``s`` (id order)."""
        cfg, upd, tri, stamp, rays = self.config, s.update, s.tri, s.stamp, s.rays
        det, previous, kal = upd.detection, upd.previous, upd.filtered
        tr: Tracks = self.tracker.tracks
        num_t, num_j = len(tr), self.layout.num_joints
        z, r = upd.measurement, upd.measurement_variance      # the tracker's gathers
        if upd.complete:
            conf_obs = tri.confidence.take(det, axis=0)
            num_views, err = tri.num_views.take(det, axis=0), tri.error_px.take(det, axis=0)
        else:                            # row K of the padded arrays is "not observed"
            conf_obs = padded(tri.confidence, 0.0).take(det, axis=0)
            num_views = padded(tri.num_views, 0).take(det, axis=0)
            err = padded(tri.error_px, np.nan).take(det, axis=0)
        accepted = kal.accepted
        every = bool(accepted.all())
        if not every:                    # a rejected observation is not an observation
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
        if every:
            conf_last = conf_obs
        else:
            conf_prev = np.where((previous >= 0)[:, None], tr.confidence, 0.0)
            conf_last = np.where(observed, conf_obs, conf_prev)
        tr.confidence = conf_last
        state, joint_var = kal.state, kal.variance
        if only is not None and only.any():
            # a ray leaves the depth open: as far as the person may have walked along it
            # since the last 3D match (a third of it per axis; the filter's isotropic
            # variance only knows the two axes across the ray)
            drift = cfg.tracking_gate_growth_mps * (stamp.s - tr.last_matched)
            joint_var = np.where(only, joint_var + (drift * drift / 3)[:, None], joint_var)
        if cfg.smoothing == 'causal':
            joints = kal.joints
        else:                            # accepted triangulations, held joints in gaps
            joints = np.where(observed[..., None], z, kal.joints)
            joint_var = np.where(observed, r, joint_var)
        missing = state == _MISSING
        confidence = np.where(missing, 0.0, np.where(state == _PREDICTED, 0.5, 1.0) * conf_last)
        velocity = tr.velocity
        source = filled(num_t, int(PositionSource.HIPS), np.uint8)
        if self._root is None:
            position, cov = np.full((num_t, 3), np.nan), np.full((num_t, 3, 3), np.nan)
        else:
            # mean of the two root joints, written out (a two-element np.mean costs more)
            left, right = self._root
            position = (joints[:, left] + joints[:, right]) / 2
            root_var = (joint_var[:, left] + joint_var[:, right]) / 4
            no_hips = ~np.isfinite(position[:, 0])
            if no_hips.any():            # never a silent origin: the body's centre instead
                position, root_var = position.copy(), root_var.copy()
                held, held_var = joints[no_hips], joint_var[no_hips]
                body = centroid(np.where(np.isfinite(held), held, tr.pose[no_hips]))
                position[no_hips] = body
                known = ~missing[no_hips] & np.isfinite(held_var)
                spread = np.where(known, held_var, 0.0).sum(axis=1) \
                    / np.maximum(known.sum(axis=1), 1)
                root_var[no_hips] = spread + BODY_ROOT_VARIANCE
                source[no_hips] = np.where(np.isfinite(body[:, 0]), int(PositionSource.BODY),
                                           int(PositionSource.NONE))
            cov = root_var[:, None, None] * _EYE3
            filt = self.tracker.filter
            v = filt.v
            root_ok = (filt.count[:, left] >= 2) & (filt.count[:, right] >= 2) \
                & ~(missing[:, left] | missing[:, right])
            velocity = np.where(root_ok[:, None], (v[:, left] + v[:, right]) / 2, velocity)
        score = confidence.sum(axis=1) / num_j if num_j else np.zeros(num_t)     # = mean
        if cfg.max_coast_s > 0:
            fade = 1.0 - (stamp.s - tr.last_observed) / cfg.max_coast_s
            score = score * np.minimum(np.maximum(fade, 0.0), 1.0)
        num_views = num_views.astype(np.uint8)
        # per-track Python values in one conversion each (numpy scalars are slow one by one)
        names = self.camera_names
        view_sets = [tuple(compress(names, row)) for row in s.track_cameras.tolist()]
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
        out.sort(key=_BY_ID)
        return out

    def tombstones(self, dead: Tracks) -> List[Track]:
        """Return the DELETED tombstones of the tracks ``dead``."""
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
