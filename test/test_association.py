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

"""Cross-view association: epipolar cost, gated Hungarian, Algorithm 1 edge cases."""

from mv3dpose_ros.core.assignment import gated_assignment
from mv3dpose_ros.core.fusion.association import (associate, camera_order,
                                                  symmetric_epipolar_distance)
from mv3dpose_ros.core.geometry.camera import essential_matrices
from mv3dpose_ros.sim.rig import make_rig
from mv3dpose_ros.sim.scene import make_scene
import numpy as np
import pytest


def _essentials(cams):
    return essential_matrices(list(cams.values()))


def _normalised(cams, joints):
    """Project world joints [P, J, 3] into every camera: list of [P, J, 2] normalised."""
    out = []
    for cam in cams.values():
        xc = joints @ cam.R.T + cam.t
        out.append(xc[..., :2] / xc[..., 2:])
    return out


def _people(rng, n, num_joints=12):
    """Blobs of joints around well separated standing positions, metres."""
    centres = np.stack([np.linspace(-2, 2, n), rng.uniform(-1.5, 1.5, n), np.ones(n)], 1)
    offsets = rng.normal(0, [0.2, 0.2, 0.5], (n, num_joints, 3))
    return centres[:, None, :] + offsets


def test_symmetric_distance_matches_explicit_line_distances():
    cams = make_rig(num_cameras=3)
    rng = np.random.default_rng(0)
    x = _normalised(cams, rng.normal([0, 0, 1], 1.0, (4, 5, 3)))
    e = _essentials(cams)
    h = [np.concatenate([p, np.ones(p.shape[:-1] + (1,))], -1) for p in x]
    new, ref = h[0][:2], h[1]
    dsum, dcnt = symmetric_epipolar_distance(new, ref, np.repeat(e[1, 0][None], len(ref), 0))
    for p in range(2):
        for m in range(4):
            total = 0.0
            for j in range(5):
                line_new = e[1, 0] @ ref[m, j]          # in camera 0
                line_ref = e[1, 0].T @ new[p, j]        # in camera 1
                d1 = abs(new[p, j] @ line_new) / np.hypot(*line_new[:2])
                d2 = abs(ref[m, j] @ line_ref) / np.hypot(*line_ref[:2])
                total += 0.5 * (d1 + d2)
            assert dsum[p, m] == pytest.approx(total, rel=1e-9)
            assert dcnt[p, m] == 5
    # projections of the same 3D points lie on each other's epipolar lines
    same = symmetric_epipolar_distance(h[0], h[1], np.repeat(e[1, 0][None], 4, 0))[0]
    assert np.allclose(np.diag(same), 0.0, atol=1e-12)


def test_missing_joints_do_not_count():
    cams = make_rig(num_cameras=2)
    rng = np.random.default_rng(1)
    x = _normalised(cams, rng.normal([0, 0, 1], 1.0, (1, 6, 3)))
    h = [np.concatenate([p, np.ones(p.shape[:-1] + (1,))], -1) for p in x]
    h[0][0, :2] = np.nan
    h[1][0, 4] = np.nan
    e = _essentials(cams)
    _, cnt = symmetric_epipolar_distance(h[0], h[1], e[1, 0][None])
    assert cnt[0, 0] == 3


def test_gated_assignment_resolves_after_veto():
    # Unconstrained optimum pairs (0, 0) and (1, 1) = 0.025 total, but (1, 1) is over the
    # threshold; the valid alternative (0, 1), (1, 0) must be found instead of dropping row 1.
    cost = np.array([[0.000, 0.015], [0.015, 0.025]])
    rows, cols = gated_assignment(cost, 0.02)
    assert sorted(zip(rows.tolist(), cols.tolist())) == [(0, 1), (1, 0)]
    rows, cols = gated_assignment(np.array([[0.5, np.nan]]), 0.02)
    assert len(rows) == 0


@pytest.mark.parametrize('num_cams', [2, 3, 5])
def test_exact_projections_are_grouped_by_person(num_cams):
    cams = make_rig(num_cameras=num_cams)
    rng = np.random.default_rng(num_cams)
    people = _people(rng, 4)
    x = _normalised(cams, people)
    perms = [rng.permutation(4) for _ in cams]
    x = [p[perm] for p, perm in zip(x, perms)]
    vis = [np.ones(p.shape[:2], bool) for p in x]
    members = associate(x, vis, _essentials(cams), threshold=0.01)
    assert members.shape == (4, num_cams)
    persons = np.array([[perms[c][m] for c, m in enumerate(row)] for row in members])
    assert all(len(set(row)) == 1 for row in persons)
    assert sorted(persons[:, 0]) == [0, 1, 2, 3]


def test_empty_views_single_view_and_all_missing_pose():
    cams = make_rig(num_cameras=4)
    rng = np.random.default_rng(3)
    people = _people(rng, 2)
    x = _normalised(cams, people)
    vis = [np.ones(p.shape[:2], bool) for p in x]
    x[0], vis[0] = x[0][:0], vis[0][:0]            # first camera empty: seed from the next
    vis[3][1] = False                               # an all-missing pose must not crash
    x[3][1] = np.nan
    members = associate(x, vis, _essentials(cams), threshold=0.01)
    assert len(members) == 2
    assert (members[:, 0] == -1).all()
    assert sorted(members[:, 3].tolist()) == [-1, 0]
    # only one camera with poses: nothing can be triangulated
    lone = [p[:0] for p in x[:3]] + [x[3]]
    lone_vis = [v[:0] for v in vis[:3]] + [vis[3]]
    assert associate(lone, lone_vis, _essentials(cams)).shape == (0, 4)
    # nothing at all
    assert associate([p[:0] for p in x], [v[:0] for v in vis], _essentials(cams)).shape == (0, 4)


def test_too_few_shared_joints_is_no_match():
    cams = make_rig(num_cameras=2)
    rng = np.random.default_rng(4)
    x = _normalised(cams, _people(rng, 1))
    vis = [np.zeros(p.shape[:2], bool) for p in x]
    vis[0][0, :6] = True
    vis[1][0, 4:] = True                            # two joints in common
    e = _essentials(cams)
    assert len(associate(x, vis, e, min_joints=3)) == 0
    assert len(associate(x, vis, e, min_joints=2)) == 1


def test_far_pose_starts_its_own_candidate_and_is_dropped():
    cams = make_rig(num_cameras=3)
    rng = np.random.default_rng(5)
    x = _normalised(cams, _people(rng, 2))
    x[2] = np.concatenate([x[2], x[2][:1] + 0.3])   # a false positive far from any line
    vis = [np.ones(p.shape[:2], bool) for p in x]
    members = associate(x, vis, _essentials(cams), threshold=0.01)
    assert len(members) == 2
    assert 2 not in members[:, 2]


def test_sim_scene_detections_associate_to_their_sources():
    scene = make_scene(num_cameras=5, num_people=4, num_frames=3, seed=11)
    names = list(scene.cameras)
    e = _essentials(scene.cameras)
    wrong = total = 0
    for t in range(scene.num_frames):
        x, vis = [], []
        for n in names:
            v = scene.views[t][n]
            x.append(scene.cameras[n].undistort(v[..., :2]))
            vis.append(v[..., 2] > 0.1)
        for row in associate(x, vis, e, threshold=0.02):
            src = [scene.sources[t][names[c]][m] for c, m in enumerate(row) if m >= 0]
            total += len(src)
            wrong += len(src) - max(src.count(s) for s in set(src))
    assert total > 0 and wrong / total < 0.02


def test_camera_order_prefers_wide_angles():
    cams = make_rig(num_cameras=8)
    order = camera_order(np.array([c.R[2] for c in cams.values()]))
    assert order[0] == 0 and sorted(order.tolist()) == list(range(8))
    assert order[1] in (2, 6)                       # 90 degrees from camera 0 on a ring of 8


def test_poses_too_sparse_to_match_are_pruned_with_identical_result():
    """Poses with < min_joints visible joints leave the dense step; nothing else changes."""
    rng = np.random.default_rng(8)
    cams = make_scene(num_cameras=4, num_people=1, num_frames=1, fps=30.0, seed=2).cameras
    joints = _people(rng, 5)
    pts = _normalised(cams, joints)
    vis = [np.ones(p.shape[:2], bool) for p in pts]
    # Noise poses with 1-2 visible joints in every view (detector debris), in front.
    debris = []
    for p, v in zip(pts, vis):
        extra = rng.uniform(-0.5, 0.5, (40, p.shape[1], 2))
        ev = np.zeros((40, p.shape[1]), bool)
        ev[:, :2] = rng.random((40, 2)) < 0.8
        debris.append((np.concatenate([extra, p]), np.concatenate([ev, v])))
    e = _essentials(cams)
    got = associate([d[0] for d in debris], [d[1] for d in debris], e, min_joints=3)
    ref = associate(pts, vis, e, min_joints=3)
    assert len(got) == len(ref) == 5
    assert sorted(map(tuple, got - 40)) == sorted(map(tuple, ref))
