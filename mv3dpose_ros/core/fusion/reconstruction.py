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
Reconstruction of one set: its 2D poses in, candidate 3D poses and the views behind them out.

Every keypoint is normalised once (``Reconstruction.points``); poses are associated across
views with cameras taken in a wide-angle-first order (``core.fusion.association``),
triangulated with a reprojection gate, single-view left/right swaps undone and implausible
bones rejected (``core.geometry.triangulation``); candidates closer than ``merge_distance_m``
seen by disjoint cameras are merged, else the weaker one is suppressed.
"""

from dataclasses import dataclass
import functools
from itertools import accumulate
from typing import Callable, Dict, Mapping, Tuple

from mv3dpose_ros.core.fusion.association import associate_stacked
from mv3dpose_ros.core.fusion.config import FusionConfig
from mv3dpose_ros.core.fusion.record import Points, SetRecord
from mv3dpose_ros.core.fusion.rig import Rig
from mv3dpose_ros.core.geometry.triangulation import (bone_length_limits, bone_outliers,
                                                      swap_pairs, swapped_views,
                                                      triangulate_robust, Triangulation)
from mv3dpose_ros.core.skeleton import Layout
from mv3dpose_ros.core.tracking.tracker import centroid, median_joint_distance
from mv3dpose_ros.core.types import Stamp
import numpy as np

#: Poses whose joint centres are further apart than the merge distance plus this [m] are not
#: compared joint by joint (a cheap test first; a few wild joints move a centre, so generous).
CENTRE_MARGIN_M = 1.0


@dataclass
class _Candidates:
    """Triangulated candidates and the views behind them (one pass of ``_triangulate``)."""

    tri: Triangulation
    members: np.ndarray     # [K, C]
    swaps: int


class Reconstruction:
    """Associate, triangulate and clean up the 2D poses of one set (paper, steps 1 and 2)."""

    def __init__(self, rig: Rig, layout: Layout, config: FusionConfig,
                 warn: Callable[[str, str], None]) -> None:
        """Precompute the layout's bone limits and flip pairs; ``warn(key, text)`` warns once."""
        self.rig, self.layout, self.config, self._warn = rig, layout, config, warn
        self._bones = np.array(layout.bones, dtype=int).reshape(-1, 2)
        self._bone_lo, self._bone_hi = bone_length_limits(layout.joint_names, layout.bones)
        self._flip_pairs = np.array(layout.flip_pairs, dtype=int).reshape(-1, 2)

    def points(self, views: Mapping[str, np.ndarray]) -> Points:
        """
        Validate the views and normalise all keypoints at once.

        Poses of unknown cameras or of the wrong shape are left out with a warning (once);
        keypoints below ``min_joint_confidence`` are missing, poses with fewer than
        ``min_pose_joints`` left are dropped.
        """
        cfg, rig = self.config, self.rig
        num_j = self.layout.num_joints
        arrays, counts = [], []
        for name in views:
            if name not in rig.index:
                self._warn('cam:' + str(name), f'view of unknown camera {name!r} ignored '
                           f'(rig cameras: {", ".join(rig.names)})')
        for name in rig.names:
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
            return Points(np.full((1, num_j, 3), np.nan), np.zeros((1, num_j)),
                          (0,) * (len(counts) + 1), _NO_ROWS, _NO_ROWS)
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
        k = rig.k.take(cam_of, axis=0)[:, None, :]                        # [N, 1, 5]
        y = (a[..., 1] - k[..., 4]) / k[..., 3]
        x = np.empty((num_n + 1, num_j, 3))
        x[:num_n, :, 0] = (a[..., 0] - k[..., 2] - k[..., 1] * y) / k[..., 0]
        x[:num_n, :, 1] = y
        x[:num_n, :, 2] = 1.0
        for c, n in enumerate(counts):
            if n and rig.distorted[c]:
                lo, hi = offsets[c], offsets[c + 1]
                x[lo:hi, :, :2] = rig.cameras[c].undistort(a[lo:hi, :, :2])
        x[:num_n][~vis] = np.nan
        x[num_n] = np.nan
        conf = np.zeros((num_n + 1, num_j))
        conf[:num_n] = np.where(vis, np.minimum(np.maximum(a[..., 2], 0.0), 1.0), 0.0)
        return Points(x, conf, offsets, cam_of, source)

    def run(self, views: Mapping[str, np.ndarray], stamp: Stamp) -> SetRecord:
        """Return the set's record: its points, candidates and the views behind them."""
        cfg = self.config
        names = self.rig.names
        present = np.array([n in views for n in names])
        sparse = bool([n for n in names if views.get(n) is None])
        pts = self.points(views)
        num_n = pts.count
        members = associate_stacked(pts.x[:num_n], pts.offsets, self.rig.essentials,
                                    threshold=cfg.epipolar_threshold_norm,
                                    min_joints=cfg.min_shared_joints,
                                    max_reference_views=cfg.max_reference_views,
                                    min_views=cfg.min_views,
                                    norm_coefficients=self.rig.norm_coef,
                                    order=self.rig.order)
        info: Dict[str, int] = {
            'poses_2d': num_n,
            'views_with_poses': len(set(pts.offsets)) - 1,     # offsets never decrease
            'candidates': len(members)}
        found = self._triangulate(pts, members)
        merged, centres = 0, None
        if len(found.members) > 1 and cfg.merge_distance_m > 0:
            centres = centroid(found.tri.joints)
            members, merged = self._merge(found.tri, found.members, centres)
            if merged:
                found, centres = self._triangulate(pts, members), None
        info.update(swapped_pairs=found.swaps, merged=merged, poses_3d=len(found.members))
        return SetRecord(stamp=stamp, present=present, sparse=sparse, points=pts,
                         tri=found.tri, members=found.members, info=info, centres=centres)

    def _triangulate(self, pts: Points, members: np.ndarray) -> _Candidates:
        """Triangulate candidates, fix swaps, check bones, drop thin candidates."""
        cfg, rig = self.config, self.rig
        g = members.T                                    # [C, K]; -1 picks the missing pose
        xg = pts.x.take(g, axis=0)
        u, v, w = xg[..., 0], xg[..., 1], pts.conf.take(g, axis=0)         # [C, K, J]
        tri = triangulate_robust(u, v, w, rig.projections, rig.focal,
                                 cfg.reprojection_gate_norm, cfg.min_views, rig.basis)
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
                sw = swapped_views(u, v, w, rig.essentials, self._flip_pairs, cfg.swap_ratio,
                                   ref_cams=self._reference_views(members),
                                   suspects=np.nonzero(suspect))
                if sw.any():
                    swaps = int(sw.sum())
                    u, v, w = swap_pairs(u, v, w, sw, self._flip_pairs)
                    tri = triangulate_robust(u, v, w, rig.projections, rig.focal,
                                             cfg.reprojection_gate_norm, cfg.min_views,
                                             rig.basis)
        if cfg.bone_check and len(members):
            bad = bone_outliers(tri.joints, self._bones, self._bone_lo, self._bone_hi,
                                tri.error)
            if bad.any():
                _reject(tri, bad)
        keep = np.isfinite(tri.joints[..., 0]).sum(axis=1) >= cfg.min_candidate_joints
        if not keep.all():
            tri = _subset(tri, keep)
            members = members[keep]
        return _Candidates(tri, members, swaps)

    def _reference_views(self, members: np.ndarray) -> np.ndarray:
        """Return ``[R, K]`` cameras: each candidate's first views in association order."""
        order = self.rig.order
        width = min(len(order), self.config.max_reference_views + 1)
        order = order.tolist()
        refs = []
        for row in members.tolist():                    # a few short rows: plain Python
            first = [c for c in order if row[c] >= 0][:width]
            refs.append(first + [-1] * (width - len(first)))
        return np.array(refs, dtype=int).reshape(-1, width).T

    def _merge(self, tri: Triangulation, members: np.ndarray, centre: np.ndarray
               ) -> Tuple[np.ndarray, int]:
        """Merge candidates closer than merge_distance_m seen by disjoint cameras; else NMS."""
        cfg = self.config
        d = centre[:, None] - centre[None]            # cheap first: centres far apart
        with np.errstate(invalid='ignore'):
            near = ((d * d).sum(axis=-1) < (cfg.merge_distance_m + CENTRE_MARGIN_M) ** 2) \
                & upper_triangle(len(centre))
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


_NO_ROWS = np.zeros(0, dtype=int)
_NO_ROWS.setflags(write=False)


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
def upper_triangle(size: int) -> np.ndarray:
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
