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
Cross-view association of 2D poses: the iterative greedy matching of Tanke & Gall (Algorithm 1).

Everything works on NORMALISED image coordinates (undistorted ``x/z, y/z``), so distances are
in normalised image units: a distance ``d`` corresponds to ``d * f`` pixels for a camera of
focal length ``f`` pixels (0.02 = 20 px at f = 1000 px, about 1.15 degrees). Thresholds
therefore do not depend on image resolution.

Essential matrices come in one array ``E[a, b]`` (``[C, C, 3, 3]``) with
``x_b^T E[a, b] x_a = 0`` for homogeneous normalised points of cameras ``a`` and ``b``, computed
once per rig (see ``core.camera.essential_matrix``).

Differences from the reference implementation: the cost is computed for all poses, candidates,
member views and joints in one vectorised expression; over-threshold pairs are removed before
the Hungarian solve, so a vetoed pair never blocks a valid alternative (the solve maximises the
number of valid matches, then minimises their total cost); any number of cameras >= 2, empty
views and poses with missing joints (even all of them) are handled.
"""

from typing import Optional, Sequence, Tuple

import numpy as np
from scipy.optimize import linear_sum_assignment

#: Cost written for infeasible pairs before the Hungarian solve (never accepted).
_INFEASIBLE = 1e6


def symmetric_epipolar_distance(
        x_new: np.ndarray, vis_new: np.ndarray,
        x_ref: np.ndarray, vis_ref: np.ndarray,
        essentials: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """
    Sum and count the symmetric point-to-epipolar-line distances of every pose pair.

    ``x_new`` [P, J, 3] homogeneous normalised points of one camera, ``x_ref`` [M, J, 3] points
    of reference poses in other cameras, ``essentials`` [M, 3, 3] with
    ``x_new^T E[m] x_ref[m] = 0``. The per-joint distance is the mean of the distance of the
    new point to the epipolar line of the reference point and vice versa. Returns
    ``(sum [P, M], count [P, M])`` over the joints visible in both poses.
    """
    lines_new = np.einsum('mab,mjb->mja', essentials, x_ref)               # in the new camera
    algebraic = np.abs(np.einsum('pja,mja->pmj', x_new, lines_new))
    lines_ref = np.einsum('pja,mab->pmjb', x_new, essentials[:, :, :2])   # in the ref camera
    norm_new = np.hypot(lines_new[..., 0], lines_new[..., 1])              # [M, J]
    norm_ref = np.hypot(lines_ref[..., 0], lines_ref[..., 1])              # [P, M, J]
    both = vis_new[:, None, :] & vis_ref[None, :, :]
    with np.errstate(divide='ignore', invalid='ignore'):
        dist = 0.5 * algebraic * (1.0 / norm_new[None] + 1.0 / norm_ref)
    both &= np.isfinite(dist)
    dist = np.where(both, dist, 0.0)
    return dist.sum(axis=2), both.sum(axis=2)


def _gated_assignment(cost: np.ndarray, threshold: float) -> Tuple[np.ndarray, np.ndarray]:
    """Solve the assignment after removing pairs at or over ``threshold`` (re-solving vetoes)."""
    feasible = cost < threshold
    if not feasible.any():
        return np.empty(0, dtype=int), np.empty(0, dtype=int)
    rows, cols = linear_sum_assignment(np.where(feasible, cost, _INFEASIBLE))
    keep = feasible[rows, cols]
    return rows[keep], cols[keep]


def associate(points: Sequence[np.ndarray], visible: Sequence[np.ndarray],
              essentials: np.ndarray, threshold: float = 0.02, min_joints: int = 3,
              max_reference_views: int = 4, min_views: int = 2,
              order: Optional[Sequence[int]] = None) -> np.ndarray:
    """
    Group the 2D poses of all cameras into person candidates (paper, Algorithm 1).

    ``points[c]`` is ``[P_c, J, 2]`` (or homogeneous ``[P_c, J, 3]``) normalised coordinates of
    camera ``c``, ``visible[c]`` the ``[P_c, J]`` joint mask. Candidates are seeded with the
    poses of the first camera (in ``order``) that has any; each further camera is matched to
    the candidates by a gated Hungarian solve on the mean symmetric epipolar distance over all
    joints visible in both the pose and a member view (``threshold`` in normalised units,
    at least ``min_joints`` shared joints per member view, at most ``max_reference_views``
    member views per candidate, those with the most visible joints, which keeps the cost linear
    in the number of cameras). Unmatched poses start new candidates. Returns ``[K, C]`` pose
    indices (-1 = not seen by that camera) of the candidates seen by at least ``min_views``
    cameras.
    """
    num_cams = len(points)
    if len(visible) != num_cams or essentials.shape[:2] != (num_cams, num_cams):
        raise ValueError(f'associate: {num_cams} point sets, {len(visible)} masks and '
                         f'essentials of shape {essentials.shape} disagree')
    order = range(num_cams) if order is None else order
    counts = np.array([len(p) for p in points], dtype=int)
    offsets = np.concatenate(([0], np.cumsum(counts)))
    if offsets[-1] == 0:
        return np.empty((0, num_cams), dtype=int)
    homog = []
    for p in points:
        p = np.asarray(p, dtype=float)
        if p.shape[-1] == 2:
            p = np.concatenate((p, np.ones(p.shape[:-1] + (1,))), axis=-1)
        homog.append(p)
    x_all = np.concatenate(homog, axis=0)                        # [N, J, 3]
    vis_all = np.concatenate([np.asarray(v, dtype=bool) for v in visible], axis=0)
    vis_all &= np.isfinite(x_all).all(axis=-1)
    joints_all = vis_all.sum(axis=1)                             # [N]

    members = np.empty((0, num_cams), dtype=int)                 # global pose index, -1 = none
    for cam in order:
        n = counts[cam]
        if n == 0:
            continue
        gidx = np.arange(offsets[cam], offsets[cam + 1])
        matched = np.zeros(n, dtype=bool)
        if len(members):
            rows, cols = _match_camera(cam, gidx, members, x_all, vis_all, joints_all,
                                       essentials, threshold, min_joints, max_reference_views)
            members[cols, cam] = gidx[rows]
            matched[rows] = True
        new = gidx[~matched]
        if len(new):
            seeds = np.full((len(new), num_cams), -1, dtype=int)
            seeds[:, cam] = new
            members = np.concatenate((members, seeds), axis=0)
    keep = (members >= 0).sum(axis=1) >= min_views
    members = members[keep]
    local = members - offsets[:-1][None, :]
    return np.where(members >= 0, local, -1)


def _match_camera(cam: int, gidx: np.ndarray, members: np.ndarray, x_all: np.ndarray,
                  vis_all: np.ndarray, joints_all: np.ndarray, essentials: np.ndarray,
                  threshold: float, min_joints: int,
                  max_reference_views: int) -> Tuple[np.ndarray, np.ndarray]:
    """Match the poses ``gidx`` of camera ``cam`` to the candidates; return (pose rows, cands)."""
    num_cands, num_cams = members.shape
    score = np.where(members >= 0, joints_all[np.maximum(members, 0)], -1)
    if num_cams > max_reference_views:
        best = np.argsort(-score, axis=1, kind='stable')[:, :max_reference_views]
        ref_cand = np.repeat(np.arange(num_cands), max_reference_views)
        ref_cam = best.ravel()
    else:
        ref_cand, ref_cam = np.indices((num_cands, num_cams)).reshape(2, -1)
    ref_pose = members[ref_cand, ref_cam]
    ok = ref_pose >= 0
    ref_cand, ref_cam, ref_pose = ref_cand[ok], ref_cam[ok], ref_pose[ok]
    dsum, dcnt = symmetric_epipolar_distance(
        x_all[gidx], vis_all[gidx], x_all[ref_pose], vis_all[ref_pose],
        essentials[ref_cam, cam])
    usable = dcnt >= min_joints
    onehot = np.zeros((len(ref_cand), num_cands))
    onehot[np.arange(len(ref_cand)), ref_cand] = 1.0
    total = np.where(usable, dsum, 0.0) @ onehot
    count = np.where(usable, dcnt, 0) @ onehot
    with np.errstate(divide='ignore', invalid='ignore'):
        cost = np.where(count > 0, total / np.maximum(count, 1), np.inf)
    return _gated_assignment(cost, threshold)
