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
once per rig (see ``core.geometry.camera.essential_matrix``).

Differences from the reference implementation: the cost is computed for all poses, candidates,
member views and joints in one vectorised expression; over-threshold pairs are removed before
the Hungarian solve, so a vetoed pair never blocks a valid alternative (the solve maximises the
number of valid matches, then minimises their total cost); any number of cameras >= 2, empty
views and poses with missing joints (even all of them) are handled.
"""

from typing import Optional, Sequence, Tuple

from mv3dpose_ros.core.assignment import gated_assignment
import numpy as np


def epipolar_norm_coefficients(essentials: np.ndarray) -> np.ndarray:
    """
    Return ``[..., 6]`` coefficients for the norms of epipolar lines ``E^T x`` (first two).

    For homogeneous ``x = (u, v, 1)``, ``|(x^T E)[:2]|^2 = q(x) . coef`` with the monomials
    ``q(x) = (u^2, v^2, 1, 2 u v, 2 u, 2 v)`` (see ``quadratic_monomials``), which turns the
    line norms of all pose pairs into one matrix product.
    """
    e = essentials[..., :, :2]
    g = e @ np.swapaxes(e, -1, -2)                                   # [..., 3, 3]
    return np.stack([g[..., 0, 0], g[..., 1, 1], g[..., 2, 2], g[..., 0, 1], g[..., 0, 2],
                     g[..., 1, 2]], axis=-1)


# quadratic_monomials as products of coordinate pairs: one gather each side instead of six ops
_Q_LEFT, _Q_RIGHT = np.array([0, 1, 2, 0, 0, 1]), np.array([0, 1, 2, 1, 2, 2])
_Q_SCALE = np.array([1.0, 1.0, 1.0, 2.0, 2.0, 2.0])


def quadratic_monomials(x: np.ndarray) -> np.ndarray:
    """Return ``(u^2, v^2, 1, 2uv, 2u, 2v)`` of homogeneous points ``[..., 3]`` (z = 1)."""
    return x[..., _Q_LEFT] * x[..., _Q_RIGHT] * _Q_SCALE


def symmetric_epipolar_distance(x_new: np.ndarray, x_ref: np.ndarray, essentials: np.ndarray,
                                q_new: Optional[np.ndarray] = None,
                                coef: Optional[np.ndarray] = None
                                ) -> Tuple[np.ndarray, np.ndarray]:
    """
    Sum and count the symmetric point-to-epipolar-line distances of pose pairs.

    ``x_new [P, J, 3]`` and ``x_ref [M, J, 3]`` are homogeneous normalised points (z = 1),
    NaN for missing joints; ``essentials [M, 3, 3]`` map each reference pose's camera to the
    new camera (``x_new^T E x_ref = 0``). The per-joint distance is the mean of the distance
    of the new point to the epipolar line of the reference point and vice versa. Optional
    precomputed ``q_new = quadratic_monomials(x_new)`` and
    ``coef = epipolar_norm_coefficients(essentials)`` save work. Returns
    ``(sum [P, M], count [P, M])`` over the joints present in both poses.
    """
    if q_new is None:
        q_new = quadratic_monomials(x_new)
    if coef is None:
        coef = epipolar_norm_coefficients(essentials)
    with np.errstate(invalid='ignore', divide='ignore'):
        return _epipolar_distance(x_new, x_ref, essentials, q_new, coef)


def _epipolar_distance(x_new, x_ref, essentials, q_new, coef):
    """Compute ``symmetric_epipolar_distance`` (NaN/inf warnings are the caller's to mute)."""
    lines = x_ref @ np.swapaxes(essentials, -1, -2)                # [M, J, 3] in the new camera
    xt = x_new.transpose(1, 0, 2)                                    # [J, P, 3]
    algebraic = np.abs(xt @ lines.transpose(1, 2, 0))                # [J, P, M]
    inv_new = 1.0 / np.hypot(lines[..., 0], lines[..., 1]).T         # [J, M]
    inv_ref = 1.0 / np.sqrt(q_new.transpose(1, 0, 2) @ coef.T)       # [J, P, M]
    dist = algebraic * (inv_new[:, None, :] + inv_ref)
    ok = np.isfinite(dist)
    return 0.5 * np.where(ok, dist, 0.0).sum(axis=0), ok.sum(axis=0)


def camera_order(axes: np.ndarray) -> np.ndarray:
    """
    Return an order of cameras for the association: wide angles between consecutive cameras.

    ``axes [C, 3]`` are the optical axes in the world (``R[2]``). Starting with camera 0, each
    next camera maximises the smallest ``|sin|`` of its angle to the cameras already taken.
    Neighbours on a ring (small baseline) are ambiguous along their epipolar lines, and an
    early wrong pairing would seed a ghost candidate; views about 90 degrees apart pair
    reliably, so they go first.
    """
    axes = np.asarray(axes, dtype=float)
    axes = axes / np.linalg.norm(axes, axis=1, keepdims=True)
    sines = np.linalg.norm(np.cross(axes[:, None], axes[None]), axis=-1)   # [C, C]
    order = [0]
    best = sines[0].copy()
    best[0] = -1.0
    for _ in range(len(axes) - 1):
        nxt = int(np.argmax(best))
        order.append(nxt)
        best = np.minimum(best, sines[nxt])
        best[order] = -1.0
    return np.array(order, dtype=int)


def associate(points: Sequence[np.ndarray], visible: Sequence[np.ndarray],
              essentials: np.ndarray, threshold: float = 0.02, min_joints: int = 3,
              max_reference_views: int = 4, min_views: int = 2) -> np.ndarray:
    """
    Group the 2D poses of all cameras into person candidates (paper, Algorithm 1).

    ``points[c]`` is ``[P_c, J, 2]`` (or homogeneous ``[P_c, J, 3]``) normalised coordinates of
    camera ``c``, ``visible[c]`` the ``[P_c, J]`` joint mask. See ``associate_stacked``; this
    returns ``[K, C]`` pose indices local to each camera (-1 = not seen by that camera).
    """
    num_cams = len(points)
    if len(visible) != num_cams or essentials.shape[:2] != (num_cams, num_cams):
        raise ValueError(f'associate: {num_cams} point sets, {len(visible)} masks and '
                         f'essentials of shape {essentials.shape} disagree')
    counts = np.array([len(p) for p in points], dtype=int)
    offsets = np.concatenate(([0], np.cumsum(counts)))
    num_j = next((np.shape(p)[1] for p in points if len(p)), 0)
    xs = []
    for p, v in zip(points, visible):
        p = np.asarray(p, dtype=float)
        if p.size == 0:
            continue
        if p.shape[-1] == 2:
            p = np.concatenate((p, np.ones(p.shape[:-1] + (1,))), axis=-1)
        xs.append(np.where(np.asarray(v, dtype=bool).reshape(p.shape[:2])[..., None], p,
                           np.nan))
    x = np.concatenate(xs, axis=0) if xs else np.zeros((0, num_j, 3))
    members = associate_stacked(x, offsets, essentials, threshold, min_joints,
                                max_reference_views, min_views)
    return np.where(members >= 0, members - offsets[:-1][None, :], -1)


def associate_stacked(x: np.ndarray, offsets: np.ndarray, essentials: np.ndarray,
                      threshold: float = 0.02, min_joints: int = 3,
                      max_reference_views: int = 4, min_views: int = 2,
                      norm_coefficients: Optional[np.ndarray] = None,
                      order: Optional[Sequence[int]] = None) -> np.ndarray:
    """
    Group stacked 2D poses into person candidates (paper, Algorithm 1).

    ``x [N, J, 3]`` holds the homogeneous normalised points of all cameras, camera ``c`` in
    rows ``offsets[c]:offsets[c + 1]``, NaN for missing joints. Candidates are seeded with the
    poses of the first camera that has any; each further camera is matched to the candidates
    by a Hungarian solve on the mean symmetric epipolar distance over all joints the pose
    shares with the candidate's reference views (``threshold`` in normalised units; a
    reference view counts when it shares at least ``min_joints`` joints; the first
    ``max_reference_views`` views of a candidate are its references, which keeps the cost
    linear in the number of cameras). Pairs at or over the threshold are removed before the
    solve, so they never block a valid alternative. Unmatched poses start new candidates.
    Returns ``[K, C]`` global pose indices (-1 = not seen) of the candidates seen by at least
    ``min_views`` cameras. ``norm_coefficients`` is
    ``epipolar_norm_coefficients(essentials)`` if precomputed; ``order`` is the sequence in
    which cameras are added (default: index order; see ``camera_order``).
    """
    num_n = len(x)
    num_c = len(offsets) - 1
    if num_n == 0:
        return np.zeros((0, num_c), dtype=int)
    if norm_coefficients is None:
        norm_coefficients = epipolar_norm_coefficients(essentials)
    q_all = quadratic_monomials(x)
    bounds = np.asarray(offsets).tolist()
    # Poses with fewer than min_joints visible joints can share min_joints with nobody: they
    # would only become single-view candidates, dropped at the end when min_views >= 2. Left
    # out of the dense step, they cost nothing (the result is the same).
    prune = min_views >= 2
    if prune:
        enough = (~np.isnan(x[..., 0])).sum(axis=1) >= min_joints
    members = np.full((num_n, num_c), -1, dtype=int)
    # Reference views (at most one per pose): pose, camera and one-hot candidate, filled in
    # place so the loop slices them instead of rebuilding arrays.
    ref_pose = np.zeros(num_n, dtype=int)
    ref_cam = np.zeros(num_n, dtype=int)
    onehot = np.zeros((num_n, num_n))
    nref: list = []
    num_m = num_k = 0
    # NaN marks missing joints and costs without a usable view: no warnings for them
    with np.errstate(invalid='ignore', divide='ignore'):
        for cam in (range(num_c) if order is None else order):
            lo, hi = bounds[cam], bounds[cam + 1]
            if prune and not enough[lo:hi].all():
                rows_of = (np.flatnonzero(enough[lo:hi]) + lo).tolist()
            else:
                rows_of = list(range(lo, hi))
            if not rows_of:
                continue
            new = list(rows_of)
            if num_k:
                rp, rc = ref_pose[:num_m], ref_cam[:num_m]
                if len(rows_of) == hi - lo:
                    x_new, q_new = x[lo:hi], q_all[lo:hi]
                else:
                    x_new, q_new = x.take(rows_of, axis=0), q_all.take(rows_of, axis=0)
                dsum, dcnt = _epipolar_distance(x_new, x.take(rp, axis=0),
                                                essentials[:, cam].take(rc, axis=0), q_new,
                                                norm_coefficients[:, cam].take(rc, axis=0))
                usable = dcnt >= min_joints
                ref_of = onehot[:num_m, :num_k]              # [M, K] reference -> candidate
                cost = (np.where(usable, dsum, 0.0) @ ref_of) / ((usable * dcnt) @ ref_of)
                rows, cols = gated_assignment(cost, threshold)   # NaN: no usable view
                for r, k in zip(rows.tolist(), cols.tolist()):
                    members[k, cam] = rows_of[r]
                    new[r] = -1
                    if nref[k] < max_reference_views:
                        ref_pose[num_m], ref_cam[num_m], onehot[num_m, k] = rows_of[r], cam, 1.0
                        num_m += 1
                        nref[k] += 1
            for n in new:
                if n >= 0:
                    members[num_k, cam] = n
                    ref_pose[num_m], ref_cam[num_m], onehot[num_m, num_k] = n, cam, 1.0
                    num_m += 1
                    nref.append(1)
                    num_k += 1
    members = members[:num_k]
    return members[(members >= 0).sum(axis=1) >= min_views]
