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

"""Tests of the camera model, undistortion, validation and epipolar geometry."""

import cv2
from mv3dpose_ros.core.geometry.camera import (CalibrationError, Camera, essential_matrix,
                                               fit_image_size, fundamental_matrix)
import numpy as np
import pytest

K = np.array([[1400.0, 0.0, 960.0], [0.0, 1390.0, 540.0], [0.0, 0.0, 1.0]])
# Strong barrel distortion as in the CMU Panoptic HD cameras.
DIST = np.array([-0.2865, 0.1851, -0.0002, 0.0007, -0.0500])


def ring(n=4, radius=5.0, height=2.5, dist=DIST):
    """Return ``n`` cameras on a circle looking at the origin."""
    cams = []
    for i in range(n):
        a = 2 * np.pi * i / n
        eye = [radius * np.cos(a), radius * np.sin(a), height]
        cams.append(Camera.look_at(f'cam{i}', K, eye, [0, 0, 1], 1920, 1080, dist=dist))
    return cams


def people_points(n=200, seed=0):
    """Return random points in a 4 m x 4 m x 2 m box around the origin."""
    rng = np.random.default_rng(seed)
    return rng.uniform([-2, -2, 0], [2, 2, 2], (n, 3))


def test_projection_matches_opencv():
    cam = ring()[1]
    X = people_points()
    rvec, _ = cv2.Rodrigues(cam.R)
    ref, _ = cv2.projectPoints(X, rvec, cam.t, cam.K, cam.dist)
    np.testing.assert_allclose(cam.project(X), ref.reshape(-1, 2), atol=1e-6)
    assert cam.in_image(cam.project(X)).all()


def test_project_shapes_nan_and_behind():
    cam = ring()[0]
    X = people_points(24).reshape(2, 3, 4, 3)
    assert cam.project(X).shape == (2, 3, 4, 2)
    X[0, 0, 0] = np.nan
    behind = cam.center + 2 * (cam.center - np.array([0, 0, 1]))
    X[1, 2, 3] = behind
    uv = cam.project(X)
    assert np.isnan(uv[0, 0, 0]).all() and np.isnan(uv[1, 2, 3]).all()
    assert np.isfinite(uv[0, 1]).all()


def test_points_beyond_the_monotonic_distortion_range_are_nan():
    cam = ring()[0]
    # 80 degrees off-axis: with k1 < 0 this would fold back into the image.
    xc = np.array([np.tan(np.radians(80)), 0.0, 1.0])
    X = cam.R.T @ (xc - cam.t)
    assert np.isnan(cam.project(X)).all()
    on_axis = cam.R.T @ (np.array([0.1, 0.05, 1.0]) - cam.t)
    assert np.isfinite(cam.project(on_axis)).all()


def test_undistort_round_trip():
    cam = ring()[2]
    X = people_points()
    xc = cam.to_camera(X)
    xy = cam.undistort(cam.project(X))
    np.testing.assert_allclose(xy, xc[:, :2] / xc[:, 2:], atol=1e-9)
    # Whole image including the corners: distort(undistort(uv)) == uv.
    u, v = np.meshgrid(np.linspace(0, 1920, 9), np.linspace(0, 1080, 7))
    uv = np.stack([u, v], axis=-1)
    np.testing.assert_allclose(cam.distort(cam.undistort(uv)), uv, atol=1e-6)
    und = cam.undistort_pixels(uv)
    np.testing.assert_allclose(und, cam.undistort(uv) @ cam.K[:2, :2].T + cam.K[:2, 2],
                               atol=1e-9)


def test_undistort_nan_and_no_distortion():
    cam = ring(dist=None)[0]
    assert not cam.has_distortion
    uv = np.array([[[960.0, 540.0], [np.nan, 3.0]], [[1100.0, 400.0], [0.0, 0.0]]])
    xy = cam.undistort(uv)
    assert xy.shape == (2, 2, 2)
    np.testing.assert_allclose(xy[0, 0], [0, 0])
    assert np.isnan(xy[0, 1]).all()
    np.testing.assert_allclose(cam.distort(xy[1]), uv[1])
    assert np.isnan(ring()[0].undistort(np.full((3, 2), np.nan))).all()
    assert ring()[0].undistort(np.zeros((0, 2))).shape == (0, 2)
    with pytest.raises(ValueError, match='shape'):
        cam.undistort(np.zeros((4, 3)))


def test_pose_properties_and_look_at():
    cam = Camera.look_at('c', K, [4, 0, 3], [0, 0, 1], 1920, 1080)
    np.testing.assert_allclose(cam.center, [4, 0, 3], atol=1e-12)
    np.testing.assert_allclose(cam.project([0, 0, 1]), K[:2, 2], atol=1e-9)
    # World up appears as image up (smaller v), the camera's left-right is not mirrored.
    assert cam.project([0, 0, 2])[1] < K[1, 2]
    assert cam.project([0, 1, 1])[0] > K[0, 2]   # +y is to the right looking along -x
    assert np.isclose(np.linalg.det(cam.R), 1)
    X = people_points(10)
    h = np.hstack([X, np.ones((10, 1))]) @ cam.P.T
    np.testing.assert_allclose(h[:, :2] / h[:, 2:], cam.project(X), atol=1e-9)
    assert cam.focal == pytest.approx(1395.0)
    again = Camera.from_pose('c', K, None, cam.R_world_cam, cam.center, 1920, 1080)
    np.testing.assert_allclose(again.t, cam.t, atol=1e-12)
    with pytest.raises(ValueError):
        cam.K[0, 0] = 1.0   # immutable by construction


@pytest.mark.parametrize('pair', [(0, 1), (0, 2), (3, 1)])
def test_epipolar_constraint(pair):
    cams = ring(4)
    a, b = cams[pair[0]], cams[pair[1]]
    X = people_points(300)
    xa, xb = a.undistort(a.project(X)), b.undistort(b.project(X))
    ha, hb = np.hstack([xa, np.ones((300, 1))]), np.hstack([xb, np.ones((300, 1))])
    E = essential_matrix(a, b)
    residual = np.einsum('ni,ij,nj->n', hb, E, ha)
    assert np.abs(residual).max() < 1e-8
    # A point off the ray breaks it (the test would catch a transposed E).
    assert np.abs(np.einsum('ni,ij,nj->n', hb[1:], E, ha[:-1])).min() > 1e-5
    assert np.linalg.matrix_rank(E, tol=1e-9) == 2
    F = fundamental_matrix(a, b)
    ua, ub = a.undistort_pixels(a.project(X)), b.undistort_pixels(b.project(X))
    ua = np.hstack([ua, np.ones((300, 1))])
    ub = np.hstack([ub, np.ones((300, 1))])
    lines = ua @ F.T                      # epipolar lines in b
    dist_px = np.abs((ub * lines).sum(1)) / np.linalg.norm(lines[:, :2], axis=1)
    assert dist_px.max() < 1e-6
    np.testing.assert_allclose(fundamental_matrix(b, a), F.T, atol=1e-12 * np.abs(F).max())


def make(**over):
    args = {'name': 'cam7', 'K': K, 'dist': DIST, 'R': np.eye(3), 't': [0, 0, 3],
            'width': 1920, 'height': 1080}
    args.update(over)
    return Camera(**args)


@pytest.mark.parametrize('over, field', [
    ({'K': np.zeros((3, 3))}, 'K'),
    ({'K': [[0, 0, 960], [0, 1390, 540], [0, 0, 1]]}, 'K'),
    ({'K': [[1400, 0, 960], [0, -5, 540], [0, 0, 1]]}, 'K'),
    ({'K': [[1400, 0, 960], [0, 1390, 540], [0, 0, 2]]}, 'K'),
    ({'K': np.eye(2)}, 'K'),
    ({'K': [[1400, 0, np.nan], [0, 1390, 540], [0, 0, 1]]}, 'K'),
    ({'K': 'identity'}, 'K'),
    ({'width': 900}, 'K'),                          # principal point outside the image
    ({'R': np.eye(3) * 1.1}, 'R'),
    ({'R': np.diag([1.0, 1.0, -1.0])}, 'R'),          # reflection
    ({'R': np.ones((3, 3))}, 'R'),
    ({'R': np.eye(4)}, 'R'),
    ({'R': [[1, 0, 0], [0, np.inf, 0], [0, 0, 1]]}, 'R'),
    ({'t': [0, 0]}, 't'),
    ({'t': [0, np.nan, 1]}, 't'),
    ({'dist': [0.1, 0.2, 0.3]}, 'dist'),
    ({'dist': [0.1, np.nan, 0, 0, 0]}, 'dist'),
    ({'width': 0}, 'width'),
    ({'height': -1080}, 'height'),
    ({'width': 1920.5}, 'width'),
    ({'height': None}, 'height'),
])
def test_validation_names_camera_and_field(over, field):
    with pytest.raises(CalibrationError) as info:
        make(**over)
    assert info.value.camera == 'cam7' and info.value.field == field
    assert "camera 'cam7'" in str(info.value) and f"field '{field}'" in str(info.value)


def test_validation_accepts_and_normalises():
    cam = make(dist=[0.1, -0.01, 0.001, 0.002], width=1920.0, t=[[0], [0], [3]])
    np.testing.assert_array_equal(cam.dist, [0.1, -0.01, 0.001, 0.002, 0.0])
    assert cam.width == 1920 and isinstance(cam.width, int) and cam.t.shape == (3,)
    assert make(dist=[]).has_distortion is False
    assert make(dist=[0.1, 0, 0, 0, 0, 0, 0, 0]).dist.shape == (5,)
    # A rotation stored with 6 digits is accepted and re-orthonormalised.
    R = np.round(cv2.Rodrigues(np.array([0.3, -1.2, 0.4]))[0], 6)
    cam = make(R=R)
    np.testing.assert_allclose(cam.R @ cam.R.T, np.eye(3), atol=1e-14)
    with pytest.raises(CalibrationError, match='name'):
        make(name='')
    err = CalibrationError('bad', camera='c', field='K').with_source('rig.yaml')
    assert str(err) == "rig.yaml: camera 'c': field 'K': bad" and isinstance(err, ValueError)


# ---------------------------------------------------------------------- image size vs calibration
def test_image_fit_same_size_is_identity():
    fit = fit_image_size(1920, 1080, 1920, 1080)
    assert fit.kind == 'same' and fit.accepted and fit.scale == (1.0, 1.0)
    poses = np.array([[[10.0, 20.0, 0.9], [0.0, 0.0, 0.0]]])
    np.testing.assert_array_equal(fit.apply(poses), poses)


def test_image_fit_resize_maps_keypoints_exactly():
    """1920x1080 calibration, 960x540 image: pixel centres map as cv2.resize maps them."""
    fit = fit_image_size(1920, 1080, 960, 540)
    assert fit.kind == 'scaled' and fit.accepted and fit.scale == (2.0, 2.0)
    assert 'resize' in fit.note and '960x540' in fit.note and '1920x1080' in fit.note
    full = np.array([[[100.5, 200.5, 0.8], [1919.5, 1079.5, 1.0], [-0.5, -0.5, 0.3]]])
    half = (full.copy() + [0.5, 0.5, 0.0]) / [2.0, 2.0, 1.0] - [0.5, 0.5, 0.0]
    half[..., 2] = full[..., 2]
    np.testing.assert_allclose(fit.apply(half), full, atol=1e-12)
    # a point at the image's pixel (0, 0) lands on the centre of the 2x2 block it came from
    np.testing.assert_allclose(fit.apply([[[0.0, 0.0, 1.0]]])[0, 0, :2], [0.5, 0.5])
    # confidence untouched, missing joints (confidence 0, zeroed) left at zero, input kept
    poses = np.array([[[10.0, 20.0, 0.5], [0.0, 0.0, 0.0]]] * 3)
    out = fit.apply(poses)
    np.testing.assert_array_equal(out[:, 1], 0.0)
    np.testing.assert_array_equal(out[..., 2], poses[..., 2])
    assert poses[0, 0, 0] == 10.0 and out.shape == (3, 2, 3)
    assert fit.apply(np.zeros((0, 17, 3))).shape == (0, 17, 3)
    # one pixel of rounding per side is still a resize (1280x720 -> 853x480)
    assert fit_image_size(1280, 720, 853, 480).kind == 'scaled'


def test_image_fit_codec_padding_is_a_crop_with_the_origin_kept():
    """Pose2Sim: videos of 1080x1920 against a calibration of 1088x1920."""
    fit = fit_image_size(1088, 1920, 1080, 1920)
    assert fit.kind == 'cropped' and fit.accepted and fit.scale == (1.0, 1.0)
    assert '8 columns' in fit.note and 'right/bottom' in fit.note and 'origin' in fit.note
    poses = np.array([[[500.25, 1700.75, 0.7]]])
    np.testing.assert_array_equal(fit.apply(poses), poses)
    assert fit_image_size(1920, 1080, 1920, 1088).kind == 'cropped'    # padded rows
    assert fit_image_size(1088, 1920, 1080, 1920, tolerance_px=7).kind == 'mismatch'
    assert fit_image_size(1088, 1920, 1080, 1920, tolerance_px=-1).kind == 'mismatch'
    assert fit_image_size(1088, 1920, 1088, 1920, tolerance_px=-1).kind == 'same'


def test_image_fit_rotated_or_unrelated_size_is_a_mismatch():
    fit = fit_image_size(1080, 1920, 1920, 1080)
    assert fit.kind == 'mismatch' and not fit.accepted
    assert 'neither a resize' in fit.note and '16 px' in fit.note
    with pytest.raises(ValueError, match='no mapping'):
        fit.apply(np.zeros((1, 17, 3)))
    assert fit_image_size(1280, 720, 640, 480).kind == 'mismatch'
    with pytest.raises(ValueError, match='positive'):
        fit_image_size(0, 1080, 1920, 1080)
