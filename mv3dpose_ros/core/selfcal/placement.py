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
Placing the cameras: the first pair, each next camera by PnP, adjustments (step 4).

Also the check that keeps a wrong camera out (``odd_cameras``: a camera whose people disagree
with where the others triangulate them) and ``refine``'s start from a given rig, which finds a
bumped camera by how far its image moves when fitted to the others' triangulations.
"""

from typing import Dict, List, Sequence, Tuple

import cv2
from mv3dpose_ros.core.geometry import bundle
from mv3dpose_ros.core.selfcal.pairs import PairResult
from mv3dpose_ros.core.selfcal.points import (drop_observations, even_sample, plausible_people,
                                              Points, subset_points)
from mv3dpose_ros.core.selfcal.views import Settings, Views
from mv3dpose_ros.core.skeleton import Layout
import numpy as np


def _observed_by(prob: bundle.Problem, cams: Sequence[int]) -> bundle.Problem:
    o = np.isin(prob.camera, list(cams))
    return bundle.Problem(prob.camera[o], prob.point[o], prob.xy[o], prob.weight[o],
                          prob.focal)


def _bundle(R, t, pts: Points, placed: Sequence[int], fixed, s: Settings,
            max_nfev: int = 50, limit: int = 0):
    """Adjust the ``placed`` cameras but ``fixed`` (one or several) and their points."""
    if limit and len(pts.frame) > limit:
        R, t, _ = _bundle(R, t, subset_points(pts, even_sample(len(pts.frame), limit, pts.person)),
                          placed, fixed, s, max_nfev)
        return R, t, bundle.triangulate(R, t, _observed_by(pts.prob, placed), len(pts.frame))
    sub = _observed_by(pts.prob, placed)
    X = bundle.triangulate(R, t, sub, len(pts.frame))
    # gross errors (wrong person matches, points behind a camera) out before adjusting:
    # a robust loss bounds their pull only once they are near, far off they steer the rig
    res = bundle.residuals_px(R, t, np.nan_to_num(X), sub)
    med = float(np.nanmedian(res)) if np.isfinite(res).any() else np.inf
    gate = np.isfinite(res) & (res < max(2 * s.outlier_px, 8 * med))
    sub = bundle.Problem(sub.camera[gate], sub.point[gate], sub.xy[gate], sub.weight[gate],
                         sub.focal)
    X = bundle.triangulate(R, t, sub, len(pts.frame))
    ok = np.isfinite(X).all(1)
    if not ok.any():
        return R, t, X
    new = np.full(len(X), -1)
    new[ok] = np.arange(ok.sum())
    o = ok[sub.point]
    sub = bundle.Problem(sub.camera[o], new[sub.point[o]], sub.xy[o], sub.weight[o], sub.focal)
    fixed_all = [c for c in range(len(R)) if c not in set(placed)] + list(np.atleast_1d(fixed))
    R, t, Xo, _ = bundle.adjust(R, t, X[ok], sub, fixed=fixed_all, loss_px=s.loss_px,
                                max_nfev=max_nfev)
    X[ok] = Xo
    return R, t, X


def _pnp(X: np.ndarray, prob: bundle.Problem, c: int, focal: float, px: float = 4.0):
    """Return camera ``c``'s ``(R, t)`` from its views of the points ``X`` (RANSAC), or None."""
    o = (prob.camera == c) & np.isfinite(X).all(1)[prob.point]
    obj, img = X[prob.point[o]], prob.xy[o]
    if len(obj) < 12:
        return None
    okp, rvec, tvec, inl = cv2.solvePnPRansac(obj, img, np.eye(3), None,
                                              reprojectionError=px / focal, iterationsCount=500,
                                              confidence=0.999, flags=cv2.SOLVEPNP_EPNP)
    if not okp or inl is None or len(inl) < 12:
        return None
    inl = inl.ravel()
    _, rvec, tvec = cv2.solvePnP(obj[inl], img[inl], np.eye(3), None, rvec, tvec, True,
                                 cv2.SOLVEPNP_ITERATIVE)
    return cv2.Rodrigues(rvec)[0], tvec.ravel()


def held_out_px(R: np.ndarray, t: np.ndarray, pts: Points, cams: Sequence[int],
                exclude: Sequence[int] = (), shift: bool = False) -> Dict[int, float]:
    """
    Return per camera the median px between its joints and the others' triangulations.

    Each camera of ``cams`` is checked against the people the other cameras (not in
    ``exclude``) triangulate without it (the best of all of them and all but one): a camera
    that sees other instants or other people, or was bumped, stands out; one fitted into an
    adjustment cannot hide its disagreement. NaN where fewer than 30 joints can be checked.
    ``shift``: instead, how far (median px) its image of those people moves when its pose is
    fitted to them: the systematic part only, which noise does not inflate (a bumped camera).
    """
    out = {}
    for c in cams:
        others = [o for o in cams if o != c and o not in set(exclude)]
        # with three others or more, also without each one: an odd camera among the others
        # must not make a good one look odd
        trials = [others] + ([[o for o in others if o != e] for e in others]
                             if len(others) >= 3 else [])
        out[c] = float('nan')
        for use in trials:
            X = bundle.triangulate(R, t, _observed_by(pts.prob, use), len(pts.frame))
            own = _observed_by(pts.prob, [c])
            r = bundle.residuals_px(R, t, X, own)
            ok = np.isfinite(r)
            if ok.sum() < 30:
                continue
            v = float(np.median(r[ok]))
            if shift:
                v = _pose_shift_px(R[c], t[c], X[own.point[ok]], own.xy[ok], r[ok],
                                   float(pts.prob.focal[c]))
            if not v >= out[c]:
                out[c] = v
    return out


def _pose_shift_px(R: np.ndarray, t: np.ndarray, X: np.ndarray, xy: np.ndarray,
                   r: np.ndarray, focal: float) -> float:
    """Return the median px the camera's image of ``X`` moves when its pose is fitted to them."""
    keep = r < max(50.0, 3 * float(np.median(r)))
    if keep.sum() < 12:
        return float('nan')
    rvec = cv2.Rodrigues(R)[0]
    rvec, tvec = cv2.solvePnPRefineLM(X[keep].reshape(-1, 1, 3), xy[keep].reshape(-1, 1, 2),
                                      np.eye(3), None, rvec.copy(), t.reshape(3, 1).copy())
    R2 = cv2.Rodrigues(rvec)[0]
    a, b = X @ R.T + t, X @ R2.T + tvec.ravel()
    with np.errstate(divide='ignore', invalid='ignore'):
        d = np.linalg.norm(a[:, :2] / a[:, 2:] - b[:, :2] / b[:, 2:], axis=1) * focal
    d = d[np.isfinite(d)]
    return float(np.median(d)) if len(d) else float('nan')


def odd_cameras(R: np.ndarray, t: np.ndarray, pts: Points, cams: Sequence[int],
                ratio: float, floor_px: float, shift: bool = False
                ) -> Tuple[List[int], Dict[int, float]]:
    """
    Return ``(odd, px)``: cameras whose ``held_out_px`` stands out, worst first, and the figures.

    One by one, the camera over ``ratio`` times the median of the rest and over ``floor_px``
    is set aside (and no longer triangulates for the others) while three cameras remain.
    """
    odd: List[int] = []
    px = held_out_px(R, t, pts, cams, shift=shift)
    while len(cams) - len(odd) >= 3:
        rest = {c: v for c, v in px.items() if c not in odd and np.isfinite(v)}
        if len(rest) < 3:
            break
        worst = max(rest, key=rest.get)
        med = float(np.median([v for c, v in rest.items() if c != worst]))
        if rest[worst] > max(floor_px, ratio * med):
            odd.append(worst)
            px = {**held_out_px(R, t, pts, cams, odd, shift), **{c: px[c] for c in odd}}
        else:
            break
    return odd, px


def initial_rig(views: Views, pts: Points, pairs: Sequence[PairResult], s: Settings):
    """Place cameras one by one: best pair by its essential matrix, the rest by PnP."""
    n = len(views.cameras)
    idx = {c: k for k, c in enumerate(views.cameras)}
    R, t = np.tile(np.eye(3), (n, 1, 1)), np.zeros((n, 3))
    best = max(pairs, key=lambda p: p.inliers)
    a, b = idx[best.a], idx[best.b]
    # correspondences of that pair through the grouped points
    prob = pts.prob
    xa = np.full((len(pts.frame), 2), np.nan)
    xb = np.full((len(pts.frame), 2), np.nan)
    xa[prob.point[prob.camera == a]] = prob.xy[prob.camera == a]
    xb[prob.point[prob.camera == b]] = prob.xy[prob.camera == b]
    ok = np.isfinite(xa).all(1) & np.isfinite(xb).all(1)
    _, Rb, tb, _ = cv2.recoverPose(best.E, xa[ok].reshape(-1, 1, 2), xb[ok].reshape(-1, 1, 2),
                                   np.eye(3))
    R[b], t[b] = Rb, tb.ravel()
    placed = [a, b]
    R, t, X = _bundle(R, t, pts, placed, a, s, 30, s.init_points)
    why = {}
    while len(placed) < n:
        finite = np.isfinite(X).all(1)
        counts = {}
        for c in range(n):
            if c in placed or views.cameras[c] in why:
                continue
            o = (prob.camera == c) & finite[prob.point]
            counts[c] = int(o.sum())
        if not counts:
            break
        c = max(counts, key=counts.get)
        name = views.cameras[c]
        if counts[c] < 30:
            why[name] = (f'sees only {counts[c]} joints the placed cameras triangulated '
                         '(need 30)')
            continue
        pose = _pnp(X, prob, c, views.focal[name])
        if pose is None:
            why[name] = 'no consistent pose from its joints (PnP found no inlier set)'
            continue
        R[c], t[c] = pose
        placed.append(c)
        R, t, X = _bundle(R, t, pts, placed, a, s, 30, s.init_points)
    return R, t, placed, why, a


def final_adjustment(R, t, pts: Points, placed: Sequence[int], fixed, s: Settings,
                     lay: Layout):
    """Adjust, drop observations far off and implausible people, adjust again."""
    R, t, X = _bundle(R, t, pts, placed, fixed, s, 50)
    res = bundle.residuals_px(R, t, X, pts.prob)
    thr = max(s.outlier_px, 5 * float(np.nanmedian(res)))
    keep = np.isfinite(res) & (res < thr) & plausible_people(X, pts, lay)[pts.prob.point]
    pts = drop_observations(pts, keep)
    R, t, X = _bundle(R, t, pts, placed, fixed, s, 50)
    return R, t, X, pts


def refine_start(R, t, pts: Points, placed: List[int], s: Settings, names, log):
    """
    Refine: find the cameras the people disagree with and re-place them; return the fixed.

    A bumped camera's joints stand out from where the other cameras triangulate them; it is
    placed again by PnP on those triangulations and adjusted alone, the others holding the
    given frame. Without such a camera all but the first move (a drifted rig).
    """
    bumped, px = odd_cameras(R, t, pts, placed, s.bumped_ratio, s.bumped_px, shift=True)
    if not bumped:
        log('refine: no camera stands out (median px its image moves when fitted to the '
            "others' triangulations: "
            + ', '.join(f'{names[c]} {v:.1f}' for c, v in px.items()) + '); adjusting all')
        return placed[0]
    good = [c for c in placed if c not in bumped]
    X = bundle.triangulate(R, t, _observed_by(pts.prob, good), len(pts.frame))
    for c in bumped:
        pose = _pnp(X, pts.prob, c, float(pts.prob.focal[c]), 2 * s.loss_px)
        if pose is not None:
            R[c], t[c] = pose
    log('refine: ' + ', '.join(f'{names[c]} ({px[c]:.1f} px)' for c in bumped)
        + " stand(s) out: fitted to the others' triangulations their image moves that much ("
        + ', '.join(f'{names[c]} {px[c]:.1f}' for c in good) + ' px): adjusted alone, '
        + ', '.join(names[c] for c in good) + ' hold the frame')
    return good
