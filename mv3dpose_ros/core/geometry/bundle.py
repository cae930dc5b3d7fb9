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
Bundle adjustment of camera extrinsics and 3D points from normalised image observations.

Intrinsics and distortion are fixed: observations are undistorted once to normalised
coordinates ``(x/z, y/z)`` and residuals are those coordinates' errors times each camera's
focal length, i.e. pixels. Confidence weights scale residuals by ``sqrt(w)``; a robust loss
(scipy's ``soft_l1``) keeps left/right swaps and detector outliers from pulling the rig.
The Jacobian is sparse (each residual depends on one camera's 6 and one point's 3 parameters),
so scipy's ``trf`` with ``lsmr`` solves rigs of tens of thousands of points in seconds.
"""

import contextlib
from dataclasses import dataclass
import glob
import os
from typing import Sequence

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import csr_matrix


def rotations(rvecs: np.ndarray) -> np.ndarray:
    """Return ``[N, 3, 3]`` rotation matrices of Rodrigues vectors ``[N, 3]`` (vectorised)."""
    rvecs = np.asarray(rvecs, dtype=float).reshape(-1, 3)
    theta = np.linalg.norm(rvecs, axis=1)
    small = theta < 1e-12
    k = rvecs / np.where(small, 1.0, theta)[:, None]
    K = np.zeros((len(rvecs), 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -k[:, 2], k[:, 1], -k[:, 0]
    K[:, 1, 0], K[:, 2, 0], K[:, 2, 1] = k[:, 2], -k[:, 1], k[:, 0]
    s, c = np.sin(theta)[:, None, None], np.cos(theta)[:, None, None]
    return np.eye(3) + s * K + (1 - c) * (K @ K)


@dataclass
class Problem:
    """
    Observations of points by cameras: ``xy[i]`` is point ``point[i]`` seen by ``camera[i]``.

    ``xy`` are normalised coordinates, ``weight`` the keypoint confidences, ``focal`` the
    cameras' focal lengths in pixels (residuals in pixels).
    """

    camera: np.ndarray     # [N] int camera index
    point: np.ndarray      # [N] int point index
    xy: np.ndarray         # [N, 2] normalised observations
    weight: np.ndarray     # [N] confidence weights
    focal: np.ndarray      # [C] focal lengths [px]


def residuals_px(R: np.ndarray, t: np.ndarray, X: np.ndarray, prob: Problem) -> np.ndarray:
    """Return the ``[N]`` unweighted reprojection errors in pixels (NaN behind a camera)."""
    xc = np.einsum('nij,nj->ni', R[prob.camera], X[prob.point]) + t[prob.camera]
    z = xc[:, 2]
    with np.errstate(divide='ignore', invalid='ignore'):
        proj = xc[:, :2] / np.where(z > 1e-9, z, np.nan)[:, None]
    return np.linalg.norm(proj - prob.xy, axis=1) * prob.focal[prob.camera]


def adjust(R: np.ndarray, t: np.ndarray, X: np.ndarray, prob: Problem,
           fixed: Sequence[int] = (0,), loss_px: float = 3.0, max_nfev: int = 50,
           rounds: int = 2):
    """
    Minimise the robust weighted reprojection error over the free cameras and all points.

    ``R [C, 3, 3]``, ``t [C, 3]``: world-to-camera; ``X [M, 3]``. Cameras in ``fixed`` hold
    the gauge (the scale stays free and is set afterwards by the world frame). Rotations are
    updated as ``exp(d) R`` with an analytic Jacobian exact at ``d = 0``, so the solve is
    repeated ``rounds`` times about the new rotations. Returns ``(R, t, X, cost)`` with
    ``cost`` scipy's final robust cost.
    """
    cost = np.nan
    with one_blas_thread():
        for _ in range(rounds):
            R, t, X, cost = _adjust_once(R, t, X, prob, fixed, loss_px, max_nfev)
    return R, t, X, cost


@contextlib.contextmanager
def one_blas_thread():
    """
    Run numpy's OpenBLAS on one thread inside the block (where it can be reached).

    ``lsmr`` makes thousands of vector-sized BLAS calls; on a busy machine a multi-threaded
    OpenBLAS spends 10-20 times longer waking its threads than computing (measured: 16 ms
    instead of 0.04 ms for a dot of 50k doubles on a loaded 2-core host).
    """
    import ctypes
    lib = get = set_ = None
    try:
        folder = os.path.join(os.path.dirname(os.path.dirname(np.__file__)), 'numpy.libs')
        for path in glob.glob(os.path.join(folder, 'libscipy_openblas*.so')):
            lib = ctypes.CDLL(path)
            get = lib.scipy_openblas_get_num_threads64_
            set_ = lib.scipy_openblas_set_num_threads64_
    except (OSError, AttributeError):
        get = set_ = None
    if get is None or set_ is None:
        yield
        return
    before = int(get())
    set_(1)
    try:
        yield
    finally:
        set_(before)


def _adjust_once(R, t, X, prob, fixed, loss_px, max_nfev):
    n_cam, n_pt = len(R), len(X)
    free = np.array([c for c in range(n_cam) if c not in set(fixed)], dtype=int)
    slot = np.full(n_cam, -1)
    slot[free] = np.arange(len(free))
    nf = len(free)
    x0 = np.concatenate([np.zeros(3 * nf), t[free].ravel(), X.ravel()])
    sw = np.sqrt(np.clip(prob.weight, 0.0, None))
    fw = (prob.focal[prob.camera] * sw)[:, None]
    n_obs = len(prob.camera)
    cs = slot[prob.camera]
    has = cs >= 0
    obs = np.arange(n_obs)

    def unpack(x):
        RR, tt = R.copy(), t.copy()
        RR[free] = rotations(x[:3 * nf].reshape(-1, 3)) @ R[free]
        tt[free] = x[3 * nf:6 * nf].reshape(-1, 3)
        return RR, tt, x[6 * nf:].reshape(n_pt, 3)

    def camera_points(x):
        RR, tt, XX = unpack(x)
        rx = np.einsum('nij,nj->ni', RR[prob.camera], XX[prob.point])
        return RR, rx, rx + tt[prob.camera]

    def fun(x):
        _, _, xc = camera_points(x)
        z = np.maximum(xc[:, 2], 1e-6)     # a point behind a camera: large but finite
        return ((xc[:, :2] / z[:, None] - prob.xy) * fw).ravel()

    # sparsity pattern: per observation two rows, 3 + 3 camera columns (if free), 3 point ones
    cols_pt = 6 * nf + 3 * prob.point[:, None] + np.arange(3)
    cols_r = 3 * cs[has, None] + np.arange(3)
    cols_t = 3 * nf + 3 * cs[has, None] + np.arange(3)

    def jac(x):
        RR, rx, xc = camera_points(x)
        z = np.maximum(xc[:, 2], 1e-6)
        D = np.zeros((n_obs, 2, 3))
        D[:, 0, 0] = D[:, 1, 1] = 1 / z
        D[:, 0, 2] = -xc[:, 0] / z ** 2
        D[:, 1, 2] = -xc[:, 1] / z ** 2
        D *= fw[:, :, None]
        d_pt = D @ RR[prob.camera]                                   # [N, 2, 3]
        skew = np.zeros((n_obs, 3, 3))
        skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = -rx[:, 2], rx[:, 1], -rx[:, 0]
        skew[:, 1, 0], skew[:, 2, 0], skew[:, 2, 1] = rx[:, 2], -rx[:, 1], rx[:, 0]
        d_rot = -D @ skew                                            # d/d(small rotation)
        rows, cols, vals = [], [], []
        for k in range(2):
            r = 2 * obs + k
            rows += [np.repeat(r, 3), np.repeat(r[has], 3), np.repeat(r[has], 3)]
            cols += [cols_pt.ravel(), cols_r.ravel(), cols_t.ravel()]
            vals += [d_pt[:, k].ravel(), d_rot[has, k].ravel(), D[has, k].ravel()]
        return csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(2 * n_obs, len(x0)))

    sol = least_squares(fun, x0, jac=jac, loss='soft_l1', f_scale=loss_px, method='trf',
                        tr_solver='lsmr', x_scale='jac', max_nfev=max_nfev, xtol=1e-10,
                        ftol=1e-8)
    RR, tt, XX = unpack(sol.x)
    return RR, tt, XX, float(sol.cost)


def triangulate(R: np.ndarray, t: np.ndarray, prob: Problem, n_points: int,
                min_views: int = 2) -> np.ndarray:
    """Return ``[M, 3]`` weighted linear (DLT) triangulations; NaN under ``min_views``."""
    P = np.concatenate([R, t[:, :, None]], axis=2)[prob.camera]        # [N, 3, 4]
    w = np.sqrt(np.clip(prob.weight, 1e-6, None))[:, None]
    rows_a = (prob.xy[:, :1] * P[:, 2] - P[:, 0]) * w
    rows_b = (prob.xy[:, 1:] * P[:, 2] - P[:, 1]) * w
    A = np.zeros((n_points, 4, 4))
    np.add.at(A, prob.point, np.einsum('ni,nj->nij', rows_a, rows_a)
              + np.einsum('ni,nj->nij', rows_b, rows_b))
    count = np.bincount(prob.point, minlength=n_points)
    out = np.full((n_points, 3), np.nan)
    ok = count >= min_views
    if ok.any():
        _, vecs = np.linalg.eigh(A[ok])
        h = vecs[:, :, 0]
        with np.errstate(divide='ignore', invalid='ignore'):
            out[ok] = h[:, :3] / h[:, 3:]
    return out
