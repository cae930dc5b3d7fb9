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

Inputs are dense over the rig and camera-major: ``u, v [C, K, J]`` normalised image coordinates
of joint ``j`` of candidate ``k`` in camera ``c`` and ``w [C, K, J]`` its weight (detector
confidence; 0 where the camera does not see the joint, then u and v are ignored), with
normalised projection matrices ``projections [C, 3, 4] = [R | t]`` (world metres -> camera).
Camera-major, contiguous arrays keep every operation a flat elementwise op or one matrix
product, which is what makes the per-step cost small. Distances are in normalised image units
(pixels / focal length) unless a name says ``_px``.

The weighted DLT solves the 3x3 normal equations of the inhomogeneous system per joint (Cramer's
rule over all joints at once), then re-weights each view by ``1 / depth^2`` once, so the
minimised residual approximates the confidence-weighted reprojection error rather than the
depth-scaled algebraic one.
"""

from dataclasses import dataclass
from typing import Dict, Optional, Sequence, Tuple

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


# Sums over x, y, z as a product with ones: several times cheaper than a last-axis sum of 3.
_XYZ = np.ones(3)


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


def dlt_basis(projections: np.ndarray) -> np.ndarray:
    """
    Return the ``[16, C * 4]`` basis of the per-view DLT normal matrices.

    The normal matrix of view ``c`` seeing normalised point ``(u, v)`` with weight ``w`` is
    ``w (u^2 + v^2) P3 P3^T - w u (P1 P3^T + P3 P1^T) - w v (P2 P3^T + P3 P2^T)
    + w (P1 P1^T + P2 P2^T)`` for the rows ``P1, P2, P3`` of ``[R | t]``, so the sum over all
    views of all joints is one matrix product of this basis with the coefficients.
    """
    p1, p2, p3 = projections[:, 0], projections[:, 1], projections[:, 2]

    def outer(a, b):
        return a[:, :, None] * b[:, None, :]

    basis = np.stack([outer(p3, p3), -(outer(p1, p3) + outer(p3, p1)),
                      -(outer(p2, p3) + outer(p3, p2)), outer(p1, p1) + outer(p2, p2)], axis=1)
    return basis.reshape(len(projections) * 4, 16).T.copy()


def _dlt_terms(u: np.ndarray, v: np.ndarray, seen: np.ndarray) -> np.ndarray:
    """
    Return the weight-free DLT coefficients ``[C, 4, K, J]`` = ``(u^2 + v^2, u, v, 1)``.

    Points not ``seen`` get ``(0, 0, 0, 1)``, so NaN never reaches the normal equations (their
    weight is 0). Filled in place: cheaper than masking and stacking four small arrays.
    """
    terms = np.zeros((u.shape[0], 4) + u.shape[1:])
    uu, vv = terms[:, 1], terms[:, 2]
    np.copyto(uu, u, where=seen)
    np.copyto(vv, v, where=seen)
    np.multiply(uu, uu, out=terms[:, 0])
    terms[:, 0] += vv * vv
    terms[:, 3] = 1.0
    return terms


# Cramer's rule on the symmetric 3x3 block ``a`` of the 4x4 normal matrix (row-major rows of
# ``dlt_basis``: a00 = 0, a01 = 1, a02 = 2, a11 = 5, a12 = 6, a22 = 10; right side -(3, 7, 11)).
# Cofactors c00, c01, c02, c11, c12, c22 = g0 * g1 - g2 * g3 with g = rows _COFACTOR_ROWS of
# m: one gather (``take``, much cheaper than fancy indexing) and three products instead of
# thirty small ones. _COFACTOR_OF lists c_ij for i, j in 0..2 (row-major).
_COFACTOR_ROWS = np.array([[5, 2, 1, 0, 1, 0], [10, 6, 6, 10, 2, 5],
                           [6, 1, 2, 2, 0, 1], [6, 10, 5, 2, 6, 1]]).ravel()
_COFACTOR_OF = np.array([0, 1, 2, 1, 3, 4, 2, 4, 5])


def _normal_solve(terms: np.ndarray, w: np.ndarray, basis: np.ndarray,
                  enough: np.ndarray) -> np.ndarray:
    """Solve the weighted DLT normal equations of all joints; return ``[3, K, J]`` (NaN: fail)."""
    c, _, k, j = terms.shape
    m = basis @ (terms * w[:, None]).reshape(c * 4, k * j)              # [16, K*J]
    g = m.take(_COFACTOR_ROWS, axis=0).reshape(4, 6, k * j)
    cof = g[0] * g[1] - g[2] * g[3]                                      # [6, K*J]
    det = (m[:3] * cof[:3]).sum(axis=0)
    trace = m[0] + m[5] + m[10]
    ok = enough.ravel() & (np.abs(det) > 1e-12 * trace * trace * trace)
    inv = np.where(ok, -1.0 / det, np.nan)        # the sign of the right side -m[3::4] rides here
    x = (cof.take(_COFACTOR_OF, axis=0).reshape(3, 3, k * j) * m[3:12:4]).sum(axis=1) * inv
    return x.reshape(3, k, j)


def triangulate_dlt(u: np.ndarray, v: np.ndarray, w: np.ndarray, projections: np.ndarray,
                    reweight: bool = True, basis: Optional[np.ndarray] = None) -> np.ndarray:
    """
    Triangulate world points ``[3, K, J]`` by confidence-weighted N-view DLT.

    ``u, v, w [C, K, J]`` (camera-major). Joints seen (w > 0) by fewer than two cameras, or
    whose normal equations are singular, come out NaN. ``basis`` is ``dlt_basis(projections)``
    if precomputed.
    """
    if basis is None:
        basis = dlt_basis(projections)
    seen = w > 0
    terms = _dlt_terms(u, v, seen)
    with np.errstate(invalid='ignore', divide='ignore'):
        return _dlt(terms, np.where(seen, w, 0.0), projections, basis, seen.sum(axis=0) >= 2,
                    reweight)


def _dlt(terms: np.ndarray, w: np.ndarray, projections: np.ndarray, basis: np.ndarray,
         enough: np.ndarray, reweight: bool = True) -> np.ndarray:
    """Run ``triangulate_dlt`` on ``_dlt_terms`` of finite points, ``w`` = 0 where unseen."""
    x = _normal_solve(terms, w, basis, enough)
    if reweight:
        depth = _depth(x, projections)
        w2 = np.where(depth > 1e-6, w / (depth * depth), 0.0)
        x2 = _normal_solve(terms, w2, basis, enough)
        x = np.where(np.isfinite(x2), x2, x)
    return x


def _depth(x: np.ndarray, projections: np.ndarray) -> np.ndarray:
    """Return the ``[C, K, J]`` depth of points ``x [3, K, J]`` in every camera."""
    k, j = x.shape[1:]
    return (projections[:, 2, :3] @ x.reshape(3, k * j) + projections[:, 2, 3:]
            ).reshape(len(projections), k, j)


def reproject(x: np.ndarray, projections: np.ndarray
              ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Project points ``x [3, K, J]`` into all cameras: ``(u, v, depth)``, each ``[C, K, J]``."""
    with np.errstate(divide='ignore', invalid='ignore'):
        return _reproject(x, projections)


def _reproject(x: np.ndarray, projections: np.ndarray
               ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    k, j = x.shape[1:]
    rows = projections.reshape(-1, 4)              # one [3C, 3] product, not C small ones
    cam = (rows[:, :3] @ x.reshape(3, k * j) + rows[:, 3:]).reshape(len(projections), 3, k, j)
    inv = 1.0 / cam[:, 2]
    return cam[:, 0] * inv, cam[:, 1] * inv, cam[:, 2]


@dataclass
class Triangulation:
    """Result of ``triangulate_robust`` for K candidates (distances normalised unless _px)."""

    joints: np.ndarray        # [K, J, 3] metres, NaN where rejected
    confidence: np.ndarray    # [K, J] mean detector confidence of the used views
    num_views: np.ndarray     # [K, J] views used
    error: np.ndarray         # [K, J] mean reprojection error of the used views, normalised
    error_px: np.ndarray      # [K, J] the same in pixels of each camera, NaN where rejected
    used: np.ndarray          # [C, K, J] bool, views that contributed
    gated: np.ndarray         # [K, J] bool, a view failed the reprojection gate (retried)
    worst_error: np.ndarray   # [K, J] largest reprojection error of a view before the gate
    view_error: np.ndarray    # [C, K, J] final reprojection error of every observation,
    #                           dropped ones included (inf: not observed)


def triangulate_robust(u: np.ndarray, v: np.ndarray, w: np.ndarray, projections: np.ndarray,
                       focal_px: np.ndarray, gate: float = 0.03, min_views: int = 2,
                       basis: Optional[np.ndarray] = None) -> Triangulation:
    """
    Triangulate with a reprojection gate and one retry without the worst view.

    ``u, v, w [C, K, J]`` as in ``triangulate_dlt``. A joint whose largest reprojection error
    over its views exceeds ``gate`` (normalised units) is triangulated again without that view
    if it has at least three; if it still fails the gate, or has fewer than ``min_views``
    views, or lies behind a camera that saw it, it is rejected (NaN).
    """
    if basis is None:
        basis = dlt_basis(projections)
    with np.errstate(invalid='ignore', divide='ignore'):
        return _triangulate_robust(u, v, w, projections, focal_px, gate, min_views, basis)


def _triangulate_robust(u, v, w, projections, focal_px, gate, min_views, basis):
    """Run ``triangulate_robust`` (inside one errstate: NaN marks missing data throughout)."""
    used = (w > 0) & np.isfinite(u) & np.isfinite(v)
    observed = used
    # Cleaned once for all solves: a dropped view keeps finite u, v and gets w = 0.
    terms = _dlt_terms(u, v, used)
    w = np.where(used, w, 0.0)
    nviews = used.sum(axis=0)
    x = _dlt(terms, w, projections, basis, nviews >= 2)
    err, depth = _errors(x, u, v, projections)
    err_used = np.where(used, err, -1.0)
    worst = err_used.max(axis=0)                                     # [K, J]
    gated = worst > gate
    retry = gated & (nviews >= 3)
    if retry.any():
        drop = (err_used == worst) & retry
        w = np.where(drop, 0.0, w)
        used = used & ~drop
        nviews = used.sum(axis=0)
        x = np.where(retry, _dlt(terms, w, projections, basis, nviews >= 2), x)
        err, depth = _errors(x, u, v, projections)
        err_used = np.where(used, err, -1.0)
    bad = (err_used.max(axis=0) > gate) | (used & ~(depth > 0)).any(axis=0) \
        | (nviews < min_views) | np.isnan(x[0])
    used = used & ~bad
    nviews = np.where(bad, 0, nviews)
    inv = np.where(bad, np.nan, 1.0 / nviews)
    err_used = np.where(used, err, 0.0)
    conf = np.where(bad, 0.0, w.sum(axis=0) * inv)                  # w is 0 where not used
    err_mean = err_used.sum(axis=0) * inv
    err_px = (err_used * focal_px[:, None, None]).sum(axis=0) * inv
    joints = np.where(bad, np.nan, x).transpose(1, 2, 0)
    return Triangulation(joints=joints, confidence=conf, num_views=nviews, error=err_mean,
                         error_px=err_px, used=used, gated=gated, worst_error=worst,
                         view_error=np.where(observed, err, np.inf))


def _errors(x: np.ndarray, u: np.ndarray, v: np.ndarray,
            projections: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Return reprojection errors (inf where undefined) and depths, ``[C, K, J]`` each."""
    pu, pv, depth = _reproject(x, projections)
    err = np.hypot(pu - u, pv - v)
    return np.where(np.isnan(err), np.inf, err), depth


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
    d = joints.take(a, axis=1) - joints.take(b, axis=1)
    length = np.sqrt((d * d) @ _XYZ)                                  # [K, B]
    bad = (length < lo) | (length > hi)                               # NaN -> False
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


def swapped_views(u: np.ndarray, v: np.ndarray, w: np.ndarray, essentials: np.ndarray,
                  flip_pairs: np.ndarray, ratio: float = 0.5,
                  ref_cams: Optional[np.ndarray] = None,
                  suspects: Optional[Tuple[np.ndarray, np.ndarray, np.ndarray]] = None
                  ) -> np.ndarray:
    """
    Find single views whose left/right labels of a joint pair are swapped.

    Works in 2D, view against view, so a mislabelled view cannot contaminate the test (a
    triangulation would be pulled towards it). For a view ``p`` of a candidate, a joint pair
    ``(a, b)`` and a reference view ``r`` of the same candidate, the symmetric epipolar
    distances of the labels as given, ``d(a_p, a_r) + d(b_p, b_r)``, are compared with the
    crossed ones, ``d(a_p, b_r) + d(b_p, a_r)``. The view is swapped when the crossed labels
    fit better by ``ratio`` against a strict majority, and at least two, of its references:
    one swapped view among three or more disagrees with all others, while the others disagree
    only with it. ``u, v, w [C, K, J]`` are camera-major normalised points and weights,
    ``essentials [C, C, 3, 3]`` with ``x_b^T E[a, b] x_a = 0``; ``ref_cams [R, K]`` the
    reference cameras of each candidate (-1 = none; default every camera), a few of which
    keep the cost linear in the number of cameras; ``suspects`` = ``(c, k, f)`` index arrays
    of the (view, candidate, pair) triples to test (default: all). Returns ``[C, K, F]``
    booleans.
    """
    fp = np.asarray(flip_pairs, dtype=int).reshape(-1, 2)
    num_c, num_k, num_j = w.shape
    out = np.zeros((num_c, num_k, len(fp)), dtype=bool)
    if num_k == 0 or len(fp) == 0 or num_c < 3:
        return out
    if ref_cams is None:
        ref_cams = np.repeat(np.arange(num_c)[:, None], num_k, axis=1)
    if suspects is None:
        suspects = np.nonzero((w[:, :, fp[:, 0]] > 0) & (w[:, :, fp[:, 1]] > 0))
    sc, sk, sf = (np.asarray(i, dtype=int) for i in suspects)
    if len(sc) == 0:
        return out
    jab = fp.take(sf, axis=0)                                            # [S, 2]
    refs = ref_cams.take(sk, axis=1).T                                   # [S, R]
    rc = np.maximum(refs, 0)
    # Flat indices into [C, K, J] of the labels (a, b) of the suspect view [S, 2] and of each
    # reference [S, R, 2], and into [C, C] of the pair (reference, suspect): ``take`` on flat
    # indices is several times cheaper than fancy indexing with index tuples.
    in_cell = sk[:, None] * num_j + jab                                  # [S, 2]
    at_p = (sc * (num_k * num_j))[:, None] + in_cell
    at_r = (rc * (num_k * num_j))[..., None] + in_cell[:, None, :]
    pair = rc * num_c + sc[:, None]
    xh = np.empty(w.shape + (3,))                                        # homogeneous points
    xh[..., 0], xh[..., 1], xh[..., 2] = u, v, 1.0
    xh = xh.reshape(-1, 3)
    xp = xh.take(at_p, axis=0)[:, None]                                  # [S, 1, 2, 3]
    xr = xh.take(at_r, axis=0)                                           # [S, R, 2, 3]
    # contiguous operands: a transposed (strided) one makes these small products much slower
    e = essentials.reshape(-1, 3, 3).take(pair, axis=0)                  # [S, R, 3, 3]
    lines_p = xr @ np.ascontiguousarray(np.swapaxes(e, -1, -2))    # of the refs, in the suspect
    lines_r = xp @ e                                               # of the suspect, in the refs
    alg = np.abs(xp @ np.ascontiguousarray(np.swapaxes(lines_p, -1, -2)))   # [S, R, i, j]
    with np.errstate(invalid='ignore', divide='ignore'):
        inv_p = 1.0 / np.hypot(lines_p[..., 0], lines_p[..., 1])         # [S, R, j]
        inv_r = 1.0 / np.hypot(lines_r[..., 0], lines_r[..., 1])         # [S, R, i]
        # d[i, j]: symmetric distance of label i of the suspect to label j of the reference
        d = alg * (inv_p[..., None, :] + inv_r[..., :, None])
        d_same = d[..., 0, 0] + d[..., 1, 1]
        d_cross = d[..., 0, 1] + d[..., 1, 0]
        w_r = w.take(at_r)
        valid = (refs >= 0) & (refs != sc[:, None]) & (w_r[..., 0] > 0) & (w_r[..., 1] > 0) \
            & np.isfinite(d_same) & np.isfinite(d_cross)
        better = valid & (d_cross < ratio * d_same)
    n_ok, n_better = valid.sum(axis=1), better.sum(axis=1)
    w_p = w.take(at_p)
    out[sc, sk, sf] = (n_better >= 2) & (2 * n_better > n_ok) & (w_p[:, 0] > 0) & (w_p[:, 1] > 0)
    return out


def swap_pairs(u: np.ndarray, v: np.ndarray, w: np.ndarray, swapped: np.ndarray,
               flip_pairs: np.ndarray) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return copies of ``u, v, w [C, K, J]`` with the ``swapped [C, K, F]`` pairs exchanged."""
    fp = np.asarray(flip_pairs, dtype=int).reshape(-1, 2)
    c, k, f = np.nonzero(swapped)
    a, b = fp[f, 0], fp[f, 1]
    out = []
    for arr in (u, v, w):
        arr = arr.copy()
        arr[c, k, a], arr[c, k, b] = arr[c, k, b], arr[c, k, a]
        out.append(arr)
    return out[0], out[1], out[2]
