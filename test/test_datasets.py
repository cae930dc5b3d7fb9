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

"""Tests of the ground-truth loaders and their consistency with the loaded cameras."""

import json
import os
import shutil

from mv3dpose_ros.core.geometry.calibration import load_calibration
from mv3dpose_ros.core.skeleton import convert_poses, get_layout
from mv3dpose_ros.io.datasets import (CAMPUS_TEST_FRAMES, DatasetError, load_campus_gt,
                                      load_panoptic_gt, panoptic_to_world)
import numpy as np
import pytest

BAND1 = 'panoptic_160906_band1'


@pytest.fixture(scope='module')
def campus(shared_data):
    return load_campus_gt(os.path.join(shared_data, 'campus', 'actorsGT.mat'))


@pytest.fixture(scope='module')
def band1(shared_data):
    return load_panoptic_gt(os.path.join(shared_data, BAND1, 'hdPose3d_stage1_coco19'))


def test_campus_shapes_units_and_frames(campus):
    assert campus.poses.shape == (2000, 3, 14, 3) and campus.layout == 'shelf14'
    assert campus.projections.shape == (2000, 3, 3, 14, 2)
    np.testing.assert_array_equal(campus.frames, np.arange(2000))
    assert campus.annotated.sum(axis=0).tolist() == [816, 694, 665]
    assert len(CAMPUS_TEST_FRAMES) == 222 and CAMPUS_TEST_FRAMES[[0, -1]].tolist() == [350, 750]
    # Test frames with annotations per actor; unannotated actors are all-NaN.
    assert campus.annotated[CAMPUS_TEST_FRAMES].sum(axis=0).tolist() == [49, 189, 138]
    assert np.isnan(campus.poses[~campus.annotated]).all()
    assert np.isnan(campus.projections[~campus.annotated]).all()
    people = campus.poses[campus.annotated]                       # [N, 14, 3] metres
    shelf = get_layout('shelf14')
    head, ankles = people[:, shelf.index('head_top')], people[:, [0, 5]]
    height = head[:, 2] - ankles[:, :, 2].mean(axis=1)
    assert 1.4 < np.median(height) < 2.0                          # metres, z up
    assert np.abs(np.median(ankles[..., 2])) < 0.2                # feet on the z = 0 floor
    np.testing.assert_array_equal(campus.frame(400), campus.poses[400])


def test_campus_gt_reprojects_onto_actor2d(shared_data, campus):
    cams = load_calibration(os.path.join(shared_data, 'campus', 'calibration_campus.json'))
    assert list(cams) == ['0', '1', '2']
    errors = []
    for c, cam in enumerate(cams.values()):
        uv = cam.project(campus.poses)                            # [F, A, 14, 2]
        err = np.linalg.norm(uv - campus.projections[:, :, c], axis=-1)
        ok = np.isfinite(err)
        assert ok.sum() == campus.annotated.sum() * 14
        assert np.median(err[ok]) < 1.0, (cam.name, np.median(err[ok]))
        assert np.percentile(err[ok], 99) < 6.0
        errors.append(err[ok])
    assert np.median(np.concatenate(errors)) < 0.6
    # Swapping two cameras breaks it: the check can fail.
    wrong = cams['1'].project(campus.poses)
    bad = np.linalg.norm(wrong - campus.projections[:, :, 0], axis=-1)
    assert np.nanmedian(bad) > 50


def test_panoptic_band1_shapes_units_and_ids(band1):
    np.testing.assert_array_equal(band1.frames, np.arange(168, 188))
    assert band1.skipped == [] and band1.layout == 'panoptic19'
    np.testing.assert_array_equal(band1.ids, [0, 1, 2])
    assert all(len(frame) == 3 for frame in band1.bodies)
    assert np.all(np.diff(band1.univ_time) > 0)
    ids, poses = band1.as_array()
    assert poses.shape == (20, 3, 19, 4)
    xyz, conf = poses[..., :3], poses[..., 3]
    missing = np.isnan(xyz).any(axis=-1)
    assert missing.any() and (conf[missing] == 0).all() and (conf[~missing] >= 0).all()
    pan = get_layout('panoptic19')
    # z up, metres: necks above hips above ankles, ankles near the floor z = 0.
    neck, mid_hip = xyz[..., pan.index('neck'), 2], xyz[..., pan.index('mid_hip'), 2]
    ankles = xyz[..., [pan.index('left_ankle'), pan.index('right_ankle')], 2]
    assert (neck > mid_hip).all()
    low = np.isfinite(ankles) & (ankles > mid_hip[..., None])
    assert not low.any()
    assert np.nanmax(np.abs(ankles)) < 0.3 and 0.9 < np.nanmedian(neck) < 1.7
    # Panoptic's body centre is the mid-hip point (the conversion relies on it).
    hips = xyz[..., [pan.index('left_hip'), pan.index('right_hip')], :].mean(axis=-2)
    gap = np.linalg.norm(hips - xyz[..., pan.index('mid_hip'), :], axis=-1)
    assert np.nanmedian(gap) < 0.001 and np.nanpercentile(gap, 90) < 0.05
    # Bodies move little between consecutive frames (ids are stable).
    step = np.linalg.norm(np.diff(xyz[..., pan.index('neck'), :], axis=0), axis=-1)
    assert np.nanmax(step) < 0.1


def test_panoptic_gt_projects_into_the_cameras_that_face_it(shared_data, band1):
    cams = load_calibration(os.path.join(shared_data, BAND1, 'calibration_160906_band1.json'))
    _, poses = band1.as_array()
    xyz = poses[..., :3]
    pan = get_layout('panoptic19')
    facing = 0
    for cam in cams.values():
        for b in range(xyz.shape[1]):
            uv = cam.project(xyz[:, b])                                 # [F, 19, 2]
            centre = np.nanmean(uv[:, pan.index('mid_hip')], axis=0)
            # A camera faces the person when the body centre is in the middle of its image.
            if np.any(np.abs(centre - cam.K[:2, 2]) > 0.3 * np.array([cam.width, cam.height])):
                continue
            facing += 1
            seen = np.isfinite(xyz[:, b]).all(-1)
            assert cam.in_image(uv[seen]).mean() > 0.8, (cam.name, b)
            upper = uv[:, [pan.index(n) for n in ('neck', 'left_shoulder', 'right_shoulder')]]
            assert cam.in_image(upper[np.isfinite(upper).all(-1)]).all(), (cam.name, b)
    assert facing >= 35        # of 31 cameras x 3 people


def test_panoptic_world_transform():
    p = panoptic_to_world([[100.0, -150.0, 20.0]])
    np.testing.assert_allclose(p, [[1.0, 0.2, 1.5]])


def test_panoptic_bad_files_are_skipped_with_reasons(shared_data, tmp_path):
    src = os.path.join(shared_data, BAND1, 'hdPose3d_stage1_coco19')
    names = sorted(os.listdir(src))[:3]
    for name in names:
        shutil.copy(os.path.join(src, name), tmp_path / name)
    (tmp_path / 'body3DScene_00000999.json').write_text('{"bodies": [')
    (tmp_path / 'body3DScene_00000998.json').write_text(
        json.dumps({'bodies': [{'id': 0, 'joints19': [1, 2, 3]}]}))
    gt = load_panoptic_gt(str(tmp_path))
    assert len(gt.frames) == 3 and len(gt.skipped) == 2
    reasons = {os.path.basename(p): r for p, r in gt.skipped}
    assert '76 numbers' in reasons['body3DScene_00000998.json']
    assert 'body3DScene_00000999.json' in reasons
    with pytest.raises(DatasetError, match='no usable'):
        load_panoptic_gt(str(tmp_path / 'empty'))


def test_campus_bad_file(tmp_path):
    path = tmp_path / 'actorsGT.mat'
    path.write_bytes(b'not a mat file')
    with pytest.raises(DatasetError, match='actorsGT.mat'):
        load_campus_gt(str(path))
    import scipy.io
    scipy.io.savemat(str(path), {'other': np.zeros(3)})
    with pytest.raises(DatasetError, match='actor3D'):
        load_campus_gt(str(path))


def test_panoptic_gt_converts_to_shelf14(band1):
    _, poses = band1.as_array()
    shelf = convert_poses(poses, 'panoptic19', 'shelf14')
    assert shelf.shape == (20, 3, 14, 4)
    # upper_neck and head_top are derived from nose, shoulders and ears. These musicians lean
    # over their instruments, so check distances along the head rather than heights.
    mid_sho = shelf[..., [8, 9], :3].mean(axis=-2)
    to_neck = np.linalg.norm(shelf[..., 12, :3] - mid_sho, axis=-1)
    to_top = np.linalg.norm(shelf[..., 13, :3] - mid_sho, axis=-1)
    ok = np.isfinite(to_neck) & np.isfinite(to_top)
    assert ok.mean() > 0.8 and (to_top[ok] > to_neck[ok]).all()
    head = np.linalg.norm(shelf[..., 13, :3] - shelf[..., 12, :3], axis=-1)[ok]
    assert 0.15 < np.median(head) < 0.35
