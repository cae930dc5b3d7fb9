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
Multi-view triangulation of person candidates, vectorised over people, cameras and joints.

Inputs are dense over the rig: ``points [K, C, J, 2]`` normalised image coordinates of candidate
``k`` in camera ``c`` and ``weights [K, C, J]`` (0 where the camera does not see the joint), with
normalised projection matrices ``projections [C, 3, 4] = [R | t]`` (world metres -> camera).
Distances are in normalised image units (pixels / focal length) unless a name says ``_px``.

The weighted DLT solves the 3x3 normal equations of the inhomogeneous system per joint, then
re-weights each view by ``1 / depth^2`` once, so the minimised residual approximates the
confidence-weighted reprojection error rather than the depth-scaled algebraic one.
"""

from dataclasses import dataclass
from typing import Dict, Sequence, Tuple

import numpy as np

# Nominal adult bone lengths in metres, keyed by the joint-name pair (either order).
# Used only for coarse sanity limits, see ``bone_length_limits``.
_NOMINAL_BONES_M: Dict[Tuple[str, str], float] = {
    ('shoulder', 'elbow'): 0.29, ('elbow', 'wrist'): 0.26,
    ('hip', 'knee'): 0.42, ('knee', 'ankle'): 0.41,
    ('shoulder', 'hip'): 0.50, ('left_shoulder', 'right_shoulder'): 0.36,
    ('left_hip', 'right_hip'): 0.24, ('nose', 'eye'): 0.04, ('eye', 'ear'): 0.07,
    ('ear', 'shoulder'): 0.20, ('neck', 'nose'): 0.20, ('upper_neck', 'head_top'): 0.20,
    ('upper_neck', 'nose'): 0.08, ('upper_neck', 'shoulder'): 0.20, ('neck', 'shoulder'): 0.18,
    ('neck', 'mid_hip'): 0.50, ('mid_hip', 'hip'): 0.12, ('ankle', 'heel'): 0.08,
    ('ankle', 'big_toe'): 0.16, ('big_toe', 'small_toe'): 0.05,
}


def _strip_side(name: str) -> str:
    for prefix in ('left_', 'right_'):
        if name.startswith(prefix):
            return name[len(prefix):]
    return name


def bone_length_limits(joint_names: Sequence[str], bones: Sequence[Tuple[int, int]],
                       scale_min: float = 0.4, scale_max: float = 1.8,
                       slack_m: float = 0.1, default_max_m: float = 1.0
                       ) -> Tuple[np.ndarray, np.ndarray]:
    """
    Return plausible ``(min [B], max [B])`` bone lengths in metres for a layout's bones.

    The limits are deliberately wide (children to tall adults, detector joint placement):
    ``[scale_min * nominal, scale_max * nominal + slack_m]`` for the nominal adult length of
    the bone type; bones of unknown type get ``[0, default_max_m]``. Short bones (< 0.2 m) get
    no lower limit because their 3D length is dominated by noise.
    """
    lo = np.zeros(len(bones))
    hi = np.full(len(bones), default_max_m)
    for i, (a, b) in enumerate(bones):
        na, nb = joint_names[a], joint_names[b]
        nominal = None
        for key in ((na, nb), (nb, na), (_strip_side(na), _strip_side(nb)),
                    (_strip_side(nb), _strip_side(na))):
            if key in _NOMINAL_BONES_M:
                nominal = _NOMINAL_BONES_M[key]
                break
        if nominal is None:
            continue
        hi[i] = scale_max * nominal + slack_m
        if nominal >= 0.2:
            lo[i] = scale_min * nominal
    return lo, hi


def triangulate_dlt(points: np.ndarray, weights: np.ndarray, projections: np.ndarray,
                    reweight: bool = True) -> np.ndarray:
    """
    Triangulate ``[K, J, 3]`` world points by confidence-weighted N-view DLT.

    Joints seen (weight > 0) by fewer than two cameras, or whose normal equations are
    singular, come out NaN.
    """
    pts = np.where(weights[..., None] > 0, points, 0.0)
    w = np.where(weights > 0, weights, 0.0)
    # Rows u * P3 - P1 and v * P3 - P2 of the DLT system: [K, C, J, 2, 4].
    rows = pts[..., :, None] * projections[None, :, None, 2:3, :] \
        - projections[None, :, None, :2, :]
    x = _solve(rows, w)
    if reweight:
        depth = np.einsum('ca,kja->kcj', projections[:, 2, :3], x) + projections[None, :, 2, 3:]
        with np.errstate(invalid='ignore'):
            good = np.isfinite(depth) & (depth > 1e-6)
        w2 = np.where(good, w / np.where(good, depth, 1.0) ** 2, 0.0)
        x2 = _solve(rows, w2)
        x = np.where(np.isfinite(x2), x2, x)
    return x


def _solve(rows: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Solve the weighted normal equations of the inhomogeneous DLT system per joint."""
    m = np.einsum('kcjri,kcjrl,kcj->kjil', rows, rows, w)          # [K, J, 4, 4]
    nviews = (w > 0).sum(axis=1)                                     # [K, J]
    a = m[..., :3, :3]
    b = -m[..., :3, 3]
    det = np.linalg.det(a)
    scale = np.einsum('...ii->...', a) ** 3 + 1e-300
    ok = (nviews >= 2) & (np.abs(det) > 1e-12 * scale)
    a = np.where(ok[..., None, None], a, np.eye(3))
    x = np.linalg.solve(a, b[..., None])[..., 0]
    x[~ok] = np.nan
    return x


def reproject(joints: np.ndarray, projections: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Project ``[K, J, 3]`` world points into all cameras: ``(uv [K, C, J, 2], depth)``."""
    cam = np.einsum('cab,kjb->kcja', projections[:, :, :3], joints) \
        + projections[None, :, None, :, 3]
    depth = cam[..., 2]
    with np.errstate(divide='ignore', invalid='ignore'):
        uv = cam[..., :2] / depth[..., None]
    return uv, depth


@dataclass
class Triangulation:
    """Result of ``triangulate_robust`` for K candidates (distances normalised unless _px)."""

    joints: np.ndarray        # [K, J, 3] metres, NaN where rejected
    confidence: np.ndarray    # [K, J] weighted mean detector confidence of the used views
    num_views: np.ndarray     # [K, J] views used
    error: np.ndarray         # [K, J] mean reprojection error of the used views, normalised
    error_px: np.ndarray      # [K, J] the same in pixels of each camera, NaN where rejected
    used: np.ndarray          # [K, C, J] bool, views that contributed


def triangulate_robust(points: np.ndarray, weights: np.ndarray, projections: np.ndarray,
                       focal_px: np.ndarray, gate: float = 0.03,
                       min_views: int = 2) -> Triangulation:
    """
    Triangulate with a reprojection gate and one retry without the worst view.

    A joint whose largest reprojection error over its views exceeds ``gate`` (normalised
    units) is triangulated again without that view if it has at least three; if it still
    fails the gate, or has fewer than ``min_views`` views, or lies behind a camera that saw
    it, it is rejected (NaN).
    """
    weights = np.where(np.isfinite(points).all(axis=-1), weights, 0.0)
    x = triangulate_dlt(points, weights, projections)
    err, depth = _errors(x, points, projections)
    used = weights > 0
    worst_err = np.where(used, err, -1.0)
    worst = worst_err.max(axis=1)                                    # [K, J]
    nviews = used.sum(axis=1)
    retry = (worst > gate) & (nviews >= 3)
    if retry.any():
        drop = (worst_err == worst[:, None, :]) & retry[:, None, :]
        weights = np.where(drop, 0.0, weights)
        sub = retry.any(axis=1)                                      # candidates to redo
        x_sub = triangulate_dlt(points[sub], weights[sub], projections)
        x[sub] = np.where(retry[sub][..., None], x_sub, x[sub])
        err, depth = _errors(x, points, projections)
        used = weights > 0
        nviews = used.sum(axis=1)
    with np.errstate(invalid='ignore'):
        err_used = np.where(used, err, np.nan)
        behind = (used & ~(depth > 0)).any(axis=1)
        bad = (np.nanmax(np.where(used, err, -1.0), axis=1) > gate) | behind \
            | (nviews < min_views) | ~np.isfinite(x).all(axis=-1)
    x[bad] = np.nan
    used &= ~bad[:, None, :]
    nviews = used.sum(axis=1)
    with np.errstate(invalid='ignore', divide='ignore'):
        conf = np.where(nviews > 0, np.where(used, weights, 0.0).sum(axis=1)
                        / np.maximum(nviews, 1), 0.0)
        err_mean = np.where(nviews > 0, np.nansum(np.where(used, err_used, 0.0), axis=1)
                            / np.maximum(nviews, 1), np.nan)
        err_px = np.where(used, err * focal_px[None, :, None], 0.0).sum(axis=1) \
            / np.where(nviews > 0, nviews, np.nan)
    return Triangulation(joints=x, confidence=conf, num_views=nviews, error=err_mean,
                         error_px=err_px, used=used)


def _errors(x: np.ndarray, points: np.ndarray,
            projections: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    uv, depth = reproject(x, projections)
    err = np.hypot(uv[..., 0] - points[..., 0], uv[..., 1] - points[..., 1])
    return np.where(np.isfinite(err), err, np.inf), depth


def bone_outliers(joints: np.ndarray, bones: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                  error: np.ndarray) -> np.ndarray:
    """
    Return a ``[K, J]`` mask of joints to reject because a bone has an implausible length.

    Of the two joints of a bad bone, the one in more bad bones is blamed, ties going to the
    one with the larger reprojection error ``error [K, J]``.
    """
    if len(bones) == 0 or joints.shape[0] == 0:
        return np.zeros(joints.shape[:2], dtype=bool)
    a, b = bones[:, 0], bones[:, 1]
    length = np.linalg.norm(joints[:, a] - joints[:, b], axis=-1)     # [K, B]
    with np.errstate(invalid='ignore'):
        bad = (length < lo) | (length > hi)                           # NaN -> False
    if not bad.any():
        return np.zeros(joints.shape[:2], dtype=bool)
    count = np.zeros(joints.shape[:2])
    for ends in (a, b):
        np.add.at(count, (np.nonzero(bad)[0], ends[np.nonzero(bad)[1]]), 1.0)
    e = np.nan_to_num(error, nan=0.0, posinf=1e3)
    score = count * 1e3 + np.minimum(e, 1e2)
    blame_a = score[:, a] >= score[:, b]
    out = np.zeros(joints.shape[:2], dtype=bool)
    k, bi = np.nonzero(bad)
    target = np.where(blame_a[k, bi], a[bi], b[bi])
    out[k, target] = True
    return out


def swapped_views(points: np.ndarray, weights: np.ndarray, tri: Triangulation,
                  projections: np.ndarray, flip_pairs: np.ndarray, gate: float,
                  ratio: float = 0.5) -> np.ndarray:
    """
    Find single views whose left/right labels of a joint pair are swapped.

    The triangulation ``tri`` (made robust by the reprojection gate, so one
    mislabelled view among three or more has been dropped) is projected into every view; a
    view's pair ``(a, b)`` counts as swapped when its observations fit the projections of
    ``(b, a)`` better by ``ratio`` while the given labels miss by more than ``gate``. Only
    joints triangulated from at least two views besides the tested one are checked. Returns
    ``[K, C, F]`` booleans (F = number of pairs).
    """
    fp = np.asarray(flip_pairs, dtype=int).reshape(-1, 2)
    num_k, num_c = weights.shape[:2]
    if num_k == 0 or len(fp) == 0:
        return np.zeros((num_k, num_c, len(fp)), dtype=bool)
    la, lb = fp[:, 0], fp[:, 1]
    uv, _ = reproject(tri.joints[:, np.concatenate((la, lb))], projections)  # [K, C, 2F, 2]
    pa, pb = uv[:, :, :len(fp)], uv[:, :, len(fp):]
    oa, ob = points[:, :, la], points[:, :, lb]

    def d(p, o):
        return np.hypot(p[..., 0] - o[..., 0], p[..., 1] - o[..., 1])

    with np.errstate(invalid='ignore'):
        same = d(pa, oa) + d(pb, ob)
        cross = d(pa, ob) + d(pb, oa)
        seen = (weights[:, :, la] > 0) & (weights[:, :, lb] > 0)
        own = tri.used[:, :, la] | tri.used[:, :, lb]
        others = np.minimum(tri.num_views[:, la], tri.num_views[:, lb])[:, None, :] \
            - own.astype(int)
        return seen & (others >= 2) & (same > 2 * gate) & (cross < ratio * same)


def swap_pairs(points: np.ndarray, weights: np.ndarray, swapped: np.ndarray,
               flip_pairs: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Return copies of ``points [K, C, J, 2]`` and ``weights`` with swapped pairs exchanged."""
    fp = np.asarray(flip_pairs, dtype=int).reshape(-1, 2)
    points, weights = points.copy(), weights.copy()
    k, c, f = np.nonzero(swapped)
    a, b = fp[f, 0], fp[f, 1]
    points[k, c, a], points[k, c, b] = points[k, c, b], points[k, c, a]
    weights[k, c, a], weights[k, c, b] = weights[k, c, b], weights[k, c, a]
    return points, weights
