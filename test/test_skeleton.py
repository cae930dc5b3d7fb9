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

"""Tests of the skeleton layouts and pose conversion."""

from mv3dpose_ros.core.skeleton import convert_poses, get_layout, Layout, LAYOUT_NAMES
import numpy as np
import pytest


def test_layout_names_and_sizes():
    sizes = {'coco17': 17, 'coco18': 18, 'body25': 25, 'body25b': 25, 'shelf14': 14,
             'panoptic19': 19}
    assert set(LAYOUT_NAMES) == set(sizes)
    for name, n in sizes.items():
        layout = get_layout(name)
        assert isinstance(layout, Layout)
        assert layout.name == name and layout.num_joints == n
        assert len(set(layout.joint_names)) == n
        assert get_layout(layout) is layout


def test_unknown_layout_lists_known_names():
    with pytest.raises(ValueError, match='coco17.*panoptic19'):
        get_layout('mpii16')
    with pytest.raises(ValueError, match="no joint 'neck'"):
        get_layout('coco17').index('neck')


def test_joint_orders_match_the_published_definitions():
    coco = get_layout('coco17').joint_names
    assert coco[0] == 'nose' and coco[5] == 'left_shoulder' and coco[16] == 'right_ankle'
    b25 = get_layout('body25')
    assert [b25.index(n) for n in ('neck', 'mid_hip', 'right_hip', 'left_hip', 'right_eye',
                                   'left_big_toe', 'right_heel')] == [1, 8, 9, 12, 15, 19, 24]
    # BODY_25B (Pose2Sim skeletons.py): COCO order, 17 neck (upper), 18 head, 19-24 feet.
    b25b = get_layout('body25b')
    assert b25b.joint_names[:17] == coco
    assert [b25b.index(n) for n in ('upper_neck', 'head_top', 'left_big_toe', 'left_heel',
                                    'right_big_toe', 'right_heel')] == [17, 18, 19, 21, 22, 24]
    shelf = get_layout('shelf14')
    assert [shelf.index(n) for n in ('right_ankle', 'left_hip', 'right_wrist', 'left_shoulder',
                                     'upper_neck', 'head_top')] == [0, 3, 6, 9, 12, 13]
    pan = get_layout('panoptic19')
    assert [pan.index(n) for n in ('neck', 'nose', 'mid_hip', 'left_shoulder', 'left_hip',
                                   'right_shoulder', 'right_hip', 'left_eye', 'right_ear')] == \
        [0, 1, 2, 3, 6, 9, 12, 15, 18]


@pytest.mark.parametrize('name', ['coco17', 'body25', 'body25b', 'shelf14', 'panoptic19'])
def test_bones_flip_pairs_and_roots(name):
    layout = get_layout(name)
    n = layout.num_joints
    assert all(0 <= a < n and 0 <= b < n and a != b for a, b in layout.bones)
    assert len({frozenset(b) for b in layout.bones}) == len(layout.bones)
    # The bones connect every joint into one tree-like body.
    seen, frontier = {layout.root_joints[0]}, [layout.root_joints[0]]
    while frontier:
        j = frontier.pop()
        for a, b in layout.bones:
            for x, y in ((a, b), (b, a)):
                if x == j and y not in seen:
                    seen.add(y)
                    frontier.append(y)
    assert seen == set(range(n))
    for a, b in layout.flip_pairs:
        na, nb = layout.joint_names[a], layout.joint_names[b]
        assert na.startswith('left_') and nb == 'right_' + na[5:]
    perm = layout.flip_permutation
    assert sorted(perm) == list(range(n)) and np.array_equal(perm[perm], np.arange(n))
    left, right = layout.root_joints
    assert layout.joint_names[left] == 'left_hip' and layout.joint_names[right] == 'right_hip'


def test_convert_by_name_keeps_values_and_marks_missing():
    rng = np.random.default_rng(0)
    poses = np.concatenate([rng.uniform(0, 100, (2, 3, 17, 2)),
                            rng.uniform(0.1, 1, (2, 3, 17, 1))], axis=-1)
    out = convert_poses(poses, 'coco17', 'body25')
    assert out.shape == (2, 3, 25, 3)
    src, dst = get_layout('coco17'), get_layout('body25')
    for j, name in enumerate(src.joint_names):
        np.testing.assert_array_equal(out[..., dst.index(name), :], poses[..., j, :])
    for name in ('left_heel', 'right_big_toe'):
        assert np.isnan(out[..., dst.index(name), :2]).all()
        assert (out[..., dst.index(name), 2] == 0).all()
    # Round trip back to coco17 is exact.
    np.testing.assert_array_equal(convert_poses(out, 'body25', 'coco17'), poses)


def test_derived_joints():
    coco = get_layout('coco17')
    pose = np.full((17, 4), np.nan)
    pose[:, 3] = 0.0
    pts = {'left_shoulder': [0.2, 0, 1.4], 'right_shoulder': [-0.2, 0, 1.4],
           'left_hip': [0.1, 0, 0.9], 'right_hip': [-0.1, 0, 0.9], 'nose': [0, -0.1, 1.6]}
    for name, xyz in pts.items():
        pose[coco.index(name)] = xyz + [0.9]
    pose[coco.index('right_hip'), 3] = 0.5
    b25 = convert_poses(pose, 'coco17', 'body25')
    np.testing.assert_allclose(b25[get_layout('body25').index('neck')], [0, 0, 1.4, 0.9])
    np.testing.assert_allclose(b25[get_layout('body25').index('mid_hip')], [0, 0, 0.9, 0.5])
    shelf = convert_poses(pose, 'coco17', 'shelf14')
    np.testing.assert_allclose(shelf[12], [0, -0.05, 1.5, 0.9])
    # No ears: head top from nose and shoulders.
    np.testing.assert_allclose(shelf[13], [0, -0.17, 1.74, 0.9])
    pose[coco.index('left_ear')] = [0.08, 0, 1.62, 0.8]
    pose[coco.index('right_ear')] = [-0.08, 0, 1.62, 0.8]
    shelf = convert_poses(pose, 'coco17', 'shelf14')
    np.testing.assert_allclose(shelf[13], [0, 0, 1.62 + 0.8 * 0.22, 0.8])
    # A missing input leaves the derived joint missing.
    pose[coco.index('left_shoulder'), 3] = 0.0
    pose[coco.index('left_ear'), :3] = np.nan
    b25 = convert_poses(pose, 'coco17', 'body25')
    neck = b25[get_layout('body25').index('neck')]
    assert np.isnan(neck[:3]).all() and neck[3] == 0
    assert np.isnan(convert_poses(pose, 'coco17', 'shelf14')[[12, 13], :3]).all()


def test_source_joint_wins_over_derivation():
    pose = np.arange(19 * 3, dtype=float).reshape(19, 3)
    out = convert_poses(pose, 'panoptic19', 'body25', has_confidence=False)
    b25 = get_layout('body25')
    np.testing.assert_array_equal(out[b25.index('neck')], pose[0])
    np.testing.assert_array_equal(out[b25.index('mid_hip')], pose[2])
    assert np.isnan(out[b25.index('left_heel')]).all()


def test_plain_xyz_and_bad_shapes():
    pose = np.ones((0, 14, 3))
    assert convert_poses(pose, 'shelf14', 'coco17', has_confidence=False).shape == (0, 17, 3)
    with pytest.raises(ValueError, match='shelf14'):
        convert_poses(np.zeros((5, 17, 3)), 'shelf14', 'coco17')
    with pytest.raises(ValueError, match='unknown'):
        convert_poses(np.zeros((17, 3)), 'coco17', 'h36m')


def test_openpose_coco18_is_body25_without_mid_hip_and_feet():
    body25 = get_layout('body25').joint_names
    coco18 = get_layout('coco18').joint_names
    assert coco18 == tuple(n for n in body25[:19] if n != 'mid_hip')
    poses = np.random.default_rng(3).uniform(0, 100, (2, 25, 3))
    mapped = convert_poses(poses, 'body25', 'coco18')
    np.testing.assert_array_equal(mapped, poses[:, [body25.index(n) for n in coco18]])
