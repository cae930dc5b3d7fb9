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

"""Weighted N-view DLT, reprojection gate, left/right swap check, bone-length limits."""

from mv3dpose_ros.core.geometry.camera import essential_matrices
from mv3dpose_ros.core.geometry.triangulation import (bone_length_limits, bone_outliers, reproject,
                                                      swap_pairs, swapped_views, triangulate_dlt,
                                                      triangulate_robust)
from mv3dpose_ros.core.skeleton import get_layout
from mv3dpose_ros.sim.rig import make_rig
import numpy as np
import pytest


def _rig(n):
    cams = make_rig(num_cameras=n)
    proj = np.stack([np.hstack([c.R, c.t[:, None]]) for c in cams.values()])
    focal = np.array([c.focal for c in cams.values()])
    return proj, focal


def _observe(proj, points):
    """Camera-major exact observations of world points [K, J, 3]: u, v, w [C, K, J]."""
    u, v, _ = reproject(points.transpose(2, 0, 1), proj)
    return u, v, np.ones_like(u)


def test_exact_points_are_recovered_from_two_to_six_views():
    rng = np.random.default_rng(0)
    pts = rng.uniform([-2, -2, 0], [2, 2, 2], (3, 7, 3))
    for n in (2, 3, 6):
        proj, _ = _rig(n)
        u, v, w = _observe(proj, pts)
        x = triangulate_dlt(u, v, w, proj).transpose(1, 2, 0)
        assert np.allclose(x, pts, atol=1e-9)


def test_fewer_than_two_views_is_nan():
    proj, _ = _rig(3)
    pts = np.array([[[0.0, 0.0, 1.0], [0.5, 0.2, 1.5]]])
    u, v, w = _observe(proj, pts)
    w[1:, 0, 0] = 0.0                 # joint 0 only in camera 0
    u[1:, 0, 0] = np.nan              # values of unseen views are ignored, even NaN
    x = triangulate_dlt(u, v, w, proj).transpose(1, 2, 0)
    assert np.isnan(x[0, 0]).all()
    assert np.allclose(x[0, 1], pts[0, 1])


def test_confidence_weights_pull_towards_trusted_views():
    proj, focal = _rig(4)
    pts = np.array([[[0.3, -0.2, 1.2]]])
    u, v, w = _observe(proj, pts)
    u[0] += 0.01                       # camera 0 is off by ~10 px
    w_low, w_high = w.copy(), w.copy()
    w_low[0] = 0.1
    err_low = np.linalg.norm(triangulate_dlt(u, v, w_low, proj)[:, 0, 0] - pts[0, 0])
    err_high = np.linalg.norm(triangulate_dlt(u, v, w_high, proj)[:, 0, 0] - pts[0, 0])
    assert err_low < 0.5 * err_high


def test_gate_retries_without_the_outlier_view():
    proj, focal = _rig(4)
    rng = np.random.default_rng(1)
    pts = rng.uniform([-1, -1, 0.2], [1, 1, 1.8], (2, 5, 3))
    u, v, w = _observe(proj, pts)
    u[2, 1, 3] += 0.08                 # one view of one joint is 80 px off at f = 1000
    tri = triangulate_robust(u, v, w, proj, focal, gate=0.03)
    assert tri.gated[1, 3] and tri.gated.sum() == 1
    assert tri.num_views[1, 3] == 3 and not tri.used[2, 1, 3]
    assert np.allclose(tri.joints, pts, atol=1e-9)
    assert np.nanmax(tri.error_px) < 1e-6


def test_inconsistent_two_view_joint_is_rejected():
    proj, focal = _rig(4)
    proj = proj[:2]                    # two cameras 90 degrees apart
    focal = focal[:2]
    pts = np.array([[[0.0, 0.5, 1.0], [0.2, 0.5, 1.3]]])
    u, v, w = _observe(proj, pts)
    v[1, 0, 0] += 0.1                  # off the epipolar line: no point fits both views
    tri = triangulate_robust(u, v, w, proj, focal, gate=0.03)
    assert np.isnan(tri.joints[0, 0]).all() and tri.num_views[0, 0] == 0
    assert tri.confidence[0, 0] == 0 and np.isnan(tri.error_px[0, 0])
    assert np.allclose(tri.joints[0, 1], pts[0, 1])


def test_reprojection_error_in_pixels():
    proj, focal = _rig(3)
    pts = np.array([[[0.0, 0.0, 1.0]]])
    u, v, w = _observe(proj, pts)
    rng = np.random.default_rng(2)
    u += rng.normal(0, 2.0 / focal[0], u.shape)     # ~2 px noise
    tri = triangulate_robust(u, v, w, proj, focal, gate=0.03)
    assert 0.1 < tri.error_px[0, 0] < 4.0
    assert tri.error_px[0, 0] == pytest.approx(tri.error[0, 0] * focal[0], rel=1e-6)


def test_swapped_single_view_is_detected_and_fixed():
    cams = make_rig(num_cameras=4)
    proj, focal = _rig(4)
    ess = _essentials(cams)
    lay = get_layout('coco17')
    rng = np.random.default_rng(3)
    pts = np.zeros((2, lay.num_joints, 3))
    for j, name in enumerate(lay.joint_names):
        side = 0.15 if name.startswith('left_') else -0.15 if name.startswith('right_') else 0
        pts[:, j] = [side, side, 1.7 - 0.1 * j]          # facing diagonally: every camera
    pts += rng.normal(0, 0.01, pts.shape)                # sees left and right apart
    pts[1] += [1.0, -0.5, 0.0]
    u, v, w = _observe(proj, pts)
    ka, kb = lay.index('left_knee'), lay.index('right_knee')
    mask = np.zeros((4, 2, len(lay.flip_pairs)), bool)
    mask[1, 0, list(lay.flip_pairs).index((ka, kb))] = True
    bad_u, bad_v, bad_w = swap_pairs(u, v, w, mask, lay.flip_pairs)
    # triangulating the swapped view as it is pulls the knees off
    tri = triangulate_robust(bad_u, bad_v, bad_w, proj, focal, gate=0.03)
    assert np.linalg.norm(tri.joints[0, ka] - pts[0, ka]) > 0.03
    sw = swapped_views(bad_u, bad_v, bad_w, ess, lay.flip_pairs)
    assert (sw == mask).all()
    assert not swapped_views(u, v, w, ess, lay.flip_pairs).any()
    fixed = triangulate_robust(*swap_pairs(bad_u, bad_v, bad_w, sw, lay.flip_pairs), proj,
                               focal, gate=0.03)
    assert np.allclose(fixed.joints, pts, atol=1e-9) and (fixed.num_views == 4).all()
    # with two views nobody can tell which one is swapped
    assert not swapped_views(bad_u[:2], bad_v[:2], bad_w[:2], ess[:2, :2], lay.flip_pairs).any()


def _essentials(cams):
    return essential_matrices(list(cams.values()))


def test_bone_limits_and_blame():
    lay = get_layout('coco17')
    lo, hi = bone_length_limits(lay.joint_names, lay.bones)
    i = lay.bones.index((lay.index('left_hip'), lay.index('left_knee')))
    assert 0.1 < lo[i] < 0.3 and 0.6 < hi[i] < 1.0
    face = lay.bones.index((lay.index('nose'), lay.index('left_eye')))
    assert lo[face] == 0 and hi[face] < 0.3
    # a standing pose made of plausible bones, then the left wrist thrown 1 m away
    pose = np.zeros((1, lay.num_joints, 3))
    for j, name in enumerate(lay.joint_names):
        pose[0, j] = [0.1 if 'left' in name else -0.1 if 'right' in name else 0, 0,
                      {'nose': 1.6, 'eye': 1.65, 'ear': 1.62, 'shoulder': 1.4, 'elbow': 1.12,
                       'wrist': 0.88, 'hip': 0.95, 'knee': 0.52, 'ankle': 0.1}[
                          name.replace('left_', '').replace('right_', '')]]
    bones = np.array(lay.bones)
    assert not bone_outliers(pose, bones, lo, hi, np.zeros((1, lay.num_joints))).any()
    pose[0, lay.index('left_wrist'), 0] += 1.0
    err = np.zeros((1, lay.num_joints))
    err[0, lay.index('left_wrist')] = 0.01
    bad = bone_outliers(pose, bones, lo, hi, err)
    assert np.nonzero(bad[0])[0].tolist() == [lay.index('left_wrist')]
