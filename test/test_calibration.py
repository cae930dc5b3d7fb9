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

"""Tests of the calibration readers on the real files, the rig YAML round trip and bad input."""

import glob
import itertools
import json
import os

import cv2
from mv3dpose_ros.core.geometry.calibration import (detect_format, load_calibration,
                                                    load_camera_info_yaml, matrix_to_quaternion,
                                                    PANOPTIC_TO_WORLD, quaternion_to_matrix,
                                                    save_rig_yaml)
from mv3dpose_ros.core.geometry.camera import CalibrationError, Camera, fundamental_matrix
import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment
import yaml

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RIGS = os.path.join(ROOT, 'config', 'rigs')

FILES = {
    'panoptic_demo': ('panoptic_demo/camera_parameters.json', 'panoptic', 31, (1920, 1080)),
    'panoptic_band1': ('panoptic_160906_band1/calibration_160906_band1.json', 'panoptic', 31,
                       (1920, 1080)),
    'campus': ('campus/calibration_campus.json', 'voxelpose', 3, (360, 288)),
    'shelf': ('shelf/calibration_shelf.json', 'voxelpose', 5, (1032, 776)),
    'pose2sim': ('pose2sim_multiperson/Calib_qualisys.toml', 'pose2sim', 4, (1088, 1920)),
}


def axes_meeting_point(cams):
    """Return the least-squares point closest to all optical axes."""
    A, b = np.zeros((3, 3)), np.zeros(3)
    for cam in cams:
        d = cam.R[2]
        M = np.eye(3) - np.outer(d, d)
        A += M
        b += M @ cam.center
    return np.linalg.solve(A, b)


@pytest.mark.parametrize('key', sorted(FILES))
def test_real_calibrations_are_metric_z_up_and_look_at_the_scene(shared_data, key):
    rel, fmt, count, size = FILES[key]
    path = os.path.join(shared_data, rel)
    assert detect_format(path) == fmt
    cams = load_calibration(path)
    assert len(cams) == count and all(isinstance(c, Camera) for c in cams.values())
    assert all((c.width, c.height) == size for c in cams.values())
    assert all(name == c.name for name, c in cams.items())
    centres = np.array([c.center for c in cams.values()])
    gaps = [np.linalg.norm(a - b) for a, b in itertools.combinations(centres, 2)]
    assert 0.3 < min(gaps) and max(gaps) < 25            # metres, not mm or cm
    assert (centres[:, 2] > 0.5).all() and (centres[:, 2] < 4).all()   # above a z-up floor
    target = axes_meeting_point(cams.values())
    assert -0.5 < target[2] < 2.5                          # the scene is near the floor
    for cam in cams.values():
        # World up is image up for every camera (none is mounted upside down).
        assert cam.R[1, 2] < -0.5, cam.name
        uv = cam.project(target)
        assert cam.in_image(uv), (cam.name, uv)


def test_panoptic_transform_reproduces_the_native_projection(shared_data):
    path = os.path.join(shared_data, FILES['panoptic_band1'][0])
    raw = {c['name']: c for c in json.load(open(path))['cameras']}
    cams = load_calibration(path, cameras=['00_03', '00_13'])
    assert list(cams) == ['00_03', '00_13']
    rng = np.random.default_rng(1)
    X_cm = rng.uniform([-100, -180, -100], [100, -20, 100], (50, 3))   # y down, cm
    X = X_cm @ PANOPTIC_TO_WORLD.T / 100
    assert np.allclose(X[:, 2], -X_cm[:, 1] / 100)                    # up = -y
    for name, cam in cams.items():
        c = raw[name]
        rvec, _ = cv2.Rodrigues(np.array(c['R']))
        ref, _ = cv2.projectPoints(X_cm, rvec, np.array(c['t'], float), np.array(c['K']),
                                   np.array(c['distCoef']))
        np.testing.assert_allclose(cam.project(X), ref.reshape(-1, 2), atol=1e-6)


def test_panoptic_camera_types(shared_data):
    path = os.path.join(shared_data, FILES['panoptic_band1'][0])
    all_cams = load_calibration(path, camera_types=None)
    assert len(all_cams) > 500
    vga = load_calibration(path, camera_types=['vga'])
    assert len(vga) == 479 and all((c.width, c.height) == (640, 480) for c in vga.values())
    with pytest.raises(CalibrationError, match='thermal'):
        load_calibration(path, camera_types=['thermal'])


def test_voxelpose_and_pose2sim_match_their_native_models(shared_data):
    path = os.path.join(shared_data, FILES['campus'][0])
    raw = json.load(open(path))
    X = np.random.default_rng(2).uniform([-2, 0, 0], [8, 10, 2], (40, 3))   # metres
    for name, cam in load_calibration(path).items():
        c = raw[name]
        xc = (np.array(c['R']) @ (X * 1000 - np.ravel(c['T'])).T).T
        ok = xc[:, 2] > 0
        xy = xc[ok, :2] / xc[ok, 2:]
        uv = np.stack([c['fx'] * xy[:, 0] + c['cx'], c['fy'] * xy[:, 1] + c['cy']], axis=1)
        np.testing.assert_allclose(cam.project(X[ok]), uv, atol=1e-6)   # Campus: no distortion
        assert np.isnan(cam.project(X[~ok])).all()
    path = os.path.join(shared_data, FILES['pose2sim'][0])
    X = np.random.default_rng(3).uniform([-2, -2, 0], [2, 2, 2], (40, 3))
    for cam in load_calibration(path).values():
        rvec, _ = cv2.Rodrigues(cam.R)
        ref, _ = cv2.projectPoints(X, rvec, cam.t, cam.K, cam.dist)
        np.testing.assert_allclose(cam.project(X), ref.reshape(-1, 2), atol=1e-6)


def test_pose2sim_detections_agree_with_the_epipolar_geometry(shared_data):
    """Real OpenPose people lie within 20 px of the epipolar lines of their match."""
    base = os.path.join(shared_data, 'pose2sim_multiperson')
    cams = load_calibration(os.path.join(base, 'Calib_qualisys.toml'))
    names = list(cams)

    def people(cam_index, frame):
        folder = sorted(glob.glob(os.path.join(base, 'pose', '*')))[cam_index]
        path = sorted(glob.glob(os.path.join(folder, '*.json')))[frame]
        data = json.load(open(path))
        return [np.array(p['pose_keypoints_2d'], float).reshape(25, 3) for p in data['people']]

    def cost_matrix(a, b, F, pa, pb):
        cost = np.full((len(pa), len(pb)), np.inf)
        for i, j in itertools.product(range(len(pa)), range(len(pb))):
            ok = (pa[i][:, 2] > 0.3) & (pb[j][:, 2] > 0.3)
            if ok.sum() >= 5:
                ua = np.hstack([a.undistort_pixels(pa[i][ok, :2]), np.ones((ok.sum(), 1))])
                ub = np.hstack([b.undistort_pixels(pb[j][ok, :2]), np.ones((ok.sum(), 1))])
                lines = ua @ F.T                     # epipolar lines in b
                d = np.abs((ub * lines).sum(1)) / np.linalg.norm(lines[:, :2], axis=1)
                cost[i, j] = np.median(d)
        return cost

    matched, control = [], []
    for frame in (0, 50):
        for ia, ib in ((0, 1), (1, 2), (0, 3), (2, 3)):
            a, b = cams[names[ia]], cams[names[ib]]
            pa, pb = people(ia, frame), people(ib, frame)
            cost = cost_matrix(a, b, fundamental_matrix(a, b), pa, pb)
            rows, cols = linear_sum_assignment(np.where(np.isfinite(cost), cost, 1e6))
            matched += sorted(cost[rows, cols])[:2]
            assert cost.min() < 30, cost
            # Control: the wrong direction of F gives no such agreement.
            wrong = cost_matrix(a, b, fundamental_matrix(b, a), pa, pb)
            control.append(wrong.min())
    matched = np.array(matched)
    assert np.median(matched) < 20 and (matched < 30).sum() >= 14, matched
    assert np.median(control) > 40, control


def assert_same_cameras(a, b, atol=1e-9):
    assert list(a) == list(b)
    for name in a:
        ca, cb = a[name], b[name]
        assert (ca.width, ca.height) == (cb.width, cb.height)
        for attr in ('K', 'dist', 'R', 't'):
            np.testing.assert_allclose(getattr(ca, attr), getattr(cb, attr), atol=atol,
                                       err_msg=f'{name}.{attr}')


@pytest.mark.parametrize('key', sorted(FILES))
def test_rig_yaml_round_trip(shared_data, tmp_path, key):
    cams = load_calibration(os.path.join(shared_data, FILES[key][0]))
    out = tmp_path / 'rig.yaml'
    save_rig_yaml(cams, str(out), comment='round trip\ntest')
    assert out.read_text().startswith('# round trip\n# test\n')
    assert detect_format(str(out)) == 'rig'
    assert_same_cameras(load_calibration(str(out)), cams)


def test_committed_example_rigs(shared_data):
    pairs = {'pose2sim_multiperson.yaml': (FILES['pose2sim'][0], None),
             'panoptic_demo.yaml': (FILES['panoptic_demo'][0],
                                    ['00_03', '00_06', '00_12', '00_13', '00_23']),
             'campus.yaml': (FILES['campus'][0], None),
             'shelf.yaml': (FILES['shelf'][0], None)}
    for rig, (src, names) in pairs.items():
        assert_same_cameras(load_calibration(os.path.join(RIGS, rig)),
                            load_calibration(os.path.join(shared_data, src), cameras=names))


def test_example_rig_with_intrinsics_file():
    cams = load_calibration(os.path.join(RIGS, 'example_rig.yaml'))
    assert list(cams) == ['cam0', 'cam1']
    cam1 = cams['cam1']
    assert (cam1.width, cam1.height) == (1280, 720) and cam1.K[0, 0] == 910.0
    np.testing.assert_allclose(cam1.dist, [-0.08, 0.02, 0, 0, 0])
    for cam in cams.values():   # both look at (0, 0, 1.3) with image up = world up
        np.testing.assert_allclose(cam.project([0, 0, 1.3]), cam.K[:2, 2], atol=1.0)
        assert cam.project([0, 0, 2.0])[1] < cam.K[1, 2]
    info = load_camera_info_yaml(os.path.join(RIGS, 'example_cam1_intrinsics.yaml'))
    assert info['name'] == 'cam1' and info['K'].shape == (3, 3) and info['dist'].shape == (5,)
    single = load_calibration(os.path.join(RIGS, 'example_cam1_intrinsics.yaml'))
    assert list(single) == ['cam1'] and np.allclose(single['cam1'].R, np.eye(3))


def test_quaternions():
    rng = np.random.default_rng(3)
    for rvec in rng.normal(size=(50, 3)) * 2:
        R = cv2.Rodrigues(rvec)[0]
        q = matrix_to_quaternion(R)
        assert q[3] >= 0 and np.isclose(np.linalg.norm(q), 1)
        np.testing.assert_allclose(quaternion_to_matrix(q), R, atol=1e-12)
    np.testing.assert_allclose(quaternion_to_matrix([0, 0, np.sin(0.5), np.cos(0.5)]),
                               cv2.Rodrigues(np.array([0, 0, 1.0]))[0], atol=1e-12)
    for R in (np.diag([1.0, -1, -1]), np.diag([-1.0, 1, -1]), np.diag([-1.0, -1, 1])):
        np.testing.assert_allclose(quaternion_to_matrix(matrix_to_quaternion(R)), R, atol=1e-12)


# ---------------------------------------------------------------------------- bad input
def rig_doc():
    return {'cameras': {'camA': {
        'image_width': 640, 'image_height': 480, 'K': [500, 500, 320, 240],
        'distortion': [0.0, 0.0, 0.0, 0.0, 0.0],
        'T_world_cam': {'translation': [0, -3, 1.5], 'rotation': [-0.7071068, 0, 0, 0.7071068]}}}}


def write(tmp_path, name, doc):
    path = tmp_path / name
    if isinstance(doc, str):
        path.write_text(doc)
    elif name.endswith('.json'):
        path.write_text(json.dumps(doc))
    else:
        path.write_text(yaml.safe_dump(doc))
    return str(path)


def expect_error(path, camera, field, match=None, **kwargs):
    with pytest.raises(CalibrationError) as info:
        load_calibration(path, **kwargs)
    err = info.value
    assert err.source is not None and os.path.basename(err.source) in str(err)
    assert err.camera == camera and err.field == field, str(err)
    if match:
        assert match in str(err), str(err)
    return err


def test_good_minimal_rig(tmp_path):
    cams = load_calibration(write(tmp_path, 'rig.yaml', rig_doc()))
    cam = cams['camA']
    np.testing.assert_allclose(cam.center, [0, -3, 1.5])
    # Rotation of -90 degrees about x: camera z (forward) = world +y, camera y (down) = world -z.
    np.testing.assert_allclose(cam.R[2], [0, 1, 0], atol=1e-6)
    np.testing.assert_allclose(cam.project([0, 0, 1.5]), [320, 240], atol=1e-4)


@pytest.mark.parametrize('edit, field, match', [
    (lambda c: c.pop('K'), 'K', 'missing'),
    (lambda c: c.pop('image_width'), 'image_width', 'missing'),
    (lambda c: c.pop('T_world_cam'), 'T_world_cam', 'missing'),
    (lambda c: c['T_world_cam'].pop('rotation'), 'rotation', 'missing'),
    (lambda c: c.update(K=[500, 500, 320]), 'K', '3 values'),
    (lambda c: c.update(K=[0, 0, 0, 0, 0, 0, 0, 0, 0]), 'K', 'all zeros'),
    (lambda c: c.update(K=[500, 0, 320, 0, -500, 240, 0, 0, 1]), 'K', 'focal'),
    (lambda c: c.update(K=[500, 500, 'x', 240]), 'K', 'not numeric'),
    (lambda c: c.update(image_height=0), 'height', 'positive'),
    (lambda c: c.update(distortion=[0.1, 0.2, 0.3]), 'dist', '3 values'),
    (lambda c: c.update(distortion_model='equidistant'), 'distortion_model', 'plumb_bob'),
    (lambda c: c['T_world_cam'].update(rotation=[0, 0, 0, 2]), 'T_world_cam.rotation', 'unit'),
    (lambda c: c['T_world_cam'].update(rotation=[0, 0, 1]), 'T_world_cam.rotation', '3 values'),
    (lambda c: c['T_world_cam'].update(translation=[0, float('nan'), 1]),
     'T_world_cam.translation', 'NaN'),
    # huge values: refused naming the field, not failing inside numpy with an error naming none
    (lambda c: c.update(distortion=[1e300, 0, 0, 0, 0]), 'dist', 'plausible range'),
    (lambda c: c.update(distortion=[10 ** 19, 0, 0, 0, 0]), 'dist', 'plausible range'),
    (lambda c: c.update(K=[1e12, 500, 320, 240]), 'K', 'plausible range'),
    (lambda c: c.update(image_width=10 ** 9), 'width', 'positive integer'),
    (lambda c: c['T_world_cam'].update(translation=[0, 1e300, 1]), 't', 'plausible range'),
])
def test_bad_rig_entries(tmp_path, edit, field, match):
    doc = rig_doc()
    edit(doc['cameras']['camA'])
    expect_error(write(tmp_path, 'rig.yaml', doc), 'camA', field, match)


def test_bad_files(tmp_path):
    with pytest.raises(CalibrationError, match='cannot read'):
        load_calibration(str(tmp_path / 'absent.yaml'), fmt='rig')
    with pytest.raises(CalibrationError, match='not valid YAML'):
        load_calibration(write(tmp_path, 'broken.yaml', 'cameras: [\n'))
    with pytest.raises(CalibrationError, match='not valid JSON'):
        load_calibration(write(tmp_path, 'broken.json', '{"0": '))
    with pytest.raises(CalibrationError, match='not valid TOML'):
        load_calibration(write(tmp_path, 'broken.toml', '[cam\n'))
    with pytest.raises(CalibrationError, match='extension'):
        load_calibration(write(tmp_path, 'rig.txt', 'x'))
    with pytest.raises(CalibrationError, match='neither'):
        load_calibration(write(tmp_path, 'other.yaml', {'a': 1}))
    with pytest.raises(CalibrationError, match='neither'):
        load_calibration(write(tmp_path, 'other.json', [1, 2]))
    with pytest.raises(CalibrationError, match='unknown calibration format'):
        load_calibration(write(tmp_path, 'rig.yaml', rig_doc()), fmt='kalibr')
    with pytest.raises(CalibrationError, match=r"\['nope'\] not found"):
        load_calibration(write(tmp_path, 'rig.yaml', rig_doc()), cameras=['nope'])
    with pytest.raises(CalibrationError, match='cameras'):
        load_calibration(write(tmp_path, 'empty.yaml', {'cameras': {}}))


def test_missing_intrinsics_file(tmp_path):
    doc = rig_doc()
    for key in ('K', 'image_width', 'image_height', 'distortion'):
        doc['cameras']['camA'].pop(key)
    doc['cameras']['camA']['intrinsics_file'] = 'nowhere.yaml'
    with pytest.raises(CalibrationError, match='nowhere.yaml.*cannot read'):
        load_calibration(write(tmp_path, 'rig.yaml', doc))
    info = {'image_width': 640, 'image_height': 480, 'camera_name': 'x',
            'camera_matrix': {'rows': 3, 'cols': 3, 'data': [0] * 9},
            'distortion_model': 'plumb_bob',
            'distortion_coefficients': {'rows': 1, 'cols': 5, 'data': [0] * 5}}
    write(tmp_path, 'nowhere.yaml', info)    # all-zero K, as from an uncalibrated driver
    expect_error(write(tmp_path, 'rig.yaml', doc), 'camA', 'K', 'all zeros')
    info['camera_matrix']['data'] = [500, 0, 320, 0, 500, 240, 0, 0, 1]
    info['distortion_model'] = 'equidistant'
    write(tmp_path, 'nowhere.yaml', info)
    err = expect_error(write(tmp_path, 'rig.yaml', doc), 'camA', 'distortion_model')
    assert 'nowhere.yaml' in str(err)
    info['distortion_model'] = 'rational_polynomial'
    info['distortion_coefficients']['data'] = [0.1, 0, 0, 0, 0, 0, 0, 0]
    write(tmp_path, 'nowhere.yaml', info)
    assert load_calibration(write(tmp_path, 'rig.yaml', doc))['camA'].dist[0] == 0.1
    doc['cameras']['camA'].update(distortion=[0.2, 0, 0, 0], K=[510, 510, 320, 240])
    cam = load_calibration(write(tmp_path, 'rig.yaml', doc))['camA']   # inline overrides file
    assert cam.dist[0] == 0.2 and cam.K[0, 0] == 510 and cam.width == 640
    del info['camera_matrix']
    write(tmp_path, 'nowhere.yaml', info)
    expect_error(write(tmp_path, 'rig.yaml', doc), 'camA', 'camera_matrix', 'missing')


def voxelpose_doc():
    # Camera at y = -5 m, 1.5 m high, looking along world +y (rows: camera axes in the world).
    return {'0': {'R': [[1, 0, 0], [0, 0, -1], [0, 1, 0]], 'T': [[0], [-5000], [1500]],
                  'fx': 400, 'fy': 400, 'cx': 180, 'cy': 144, 'k': [[0], [0], [0]],
                  'p': [[0], [0]]}}


def test_bad_voxelpose(tmp_path):
    doc = voxelpose_doc()
    cam = load_calibration(write(tmp_path, 'campus_ok.json', doc))['0']
    assert (cam.width, cam.height) == (360, 288)              # Campus size from the name
    np.testing.assert_allclose(cam.center, [0, -5, 1.5])
    np.testing.assert_allclose(cam.project([0, 0, 1.5]), [180, 144])
    doc['0']['R'] = [[1, 0, 0], [0, 0, 1], [0, 1, 0]]         # a reflection (det -1)
    expect_error(write(tmp_path, 'campus_bad.json', doc), '0', 'R', 'rotation')
    doc = voxelpose_doc()
    doc['0']['T'] = [1, 2]
    expect_error(write(tmp_path, 'campus_bad.json', doc), '0', 'T', '2 values')
    doc = voxelpose_doc()
    del doc['0']['fy']
    expect_error(write(tmp_path, 'campus_bad.json', doc), '0', 'fy', 'missing', fmt='voxelpose')
    doc = voxelpose_doc()
    path = write(tmp_path, 'mystery.json', doc)
    expect_error(path, '0', 'width', 'image_size')
    assert load_calibration(path, image_size=(400, 300))['0'].height == 300
    doc['0'].update(width=640, height=480)
    assert load_calibration(write(tmp_path, 'mystery.json', doc))['0'].width == 640


def test_bad_panoptic(tmp_path, shared_data):
    data = json.load(open(os.path.join(shared_data, FILES['panoptic_demo'][0])))
    data['cameras'] = [c for c in data['cameras'] if c['name'] in ('00_03', '00_06')]
    data['cameras'][1]['R'][0][0] += 0.1
    expect_error(write(tmp_path, 'pan.json', data), '00_06', 'R', 'rotation')
    data['cameras'][1]['R'][0][0] -= 0.1
    del data['cameras'][0]['distCoef']
    expect_error(write(tmp_path, 'pan.json', data), '00_03', 'distCoef', 'missing')
    data['cameras'][0]['distCoef'] = [0.1, 0.2]
    expect_error(write(tmp_path, 'pan.json', data), '00_03', 'dist', '2 values')


def test_bad_pose2sim(tmp_path, shared_data):
    text = open(os.path.join(shared_data, FILES['pose2sim'][0])).read()
    bad = text.replace('size = [ 1088.0, 1920.0]', 'size = [ 1088.0]', 1)
    expect_error(write(tmp_path, 'c.toml', bad), 'cam_01', 'size', '1 values')
    bad = text.replace('fisheye = false', 'fisheye = true', 1)
    expect_error(write(tmp_path, 'c.toml', bad), 'cam_01', 'fisheye', 'not supported')
    # Width and height swapped: the principal point falls outside the image.
    bad = text.replace('size = [ 1088.0, 1920.0]', 'size = [ 1920.0, 1088.0]', 1)
    ok = load_calibration(write(tmp_path, 'c.toml', bad))   # cx 533 < 1920, cy 948 < 1088
    assert ok['cam_01'].width == 1920
    bad = text.replace('matrix = [ [ 1681.244873046875, 0.0, 532.97369384375]',
                       'matrix = [ [ 1681.244873046875, 0.0, 1532.97369384375]', 1)
    expect_error(write(tmp_path, 'c.toml', bad), 'cam_01', 'K', 'principal point')
    with pytest.raises(CalibrationError, match='no camera'):
        load_calibration(write(tmp_path, 'c.toml', '[metadata]\nerror = 0.0\n'))


def test_hostile_files_fail_fast_naming_the_file(tmp_path):
    """An alias bomb, deep nesting and 400-digit numbers, in every format: refused at once."""
    import resource
    import time
    bomb = 'cameras: &a0 [x, x, x, x, x, x, x, x, x]\n' + ''.join(
        f'k{i}: &a{i} [' + ', '.join([f'*a{i - 1}'] * 9) + ']\n' for i in range(1, 10))
    deep = '[' * 3000 + ']' * 3000
    cases = {
        'bomb.yaml': (bomb, 'alias bomb'),
        'deep.yaml': ('cameras: ' + deep, 'nesting'),
        'deep.json': ('{"0": {"R": ' + deep + '}}', 'nesting'),
        'deep.toml': ('[cam]\nsize = ' + deep, 'nesting'),
        'digits.json': ('{"0": {"R": [' + '9' * 400 + '], "T": [0, 0, 0], "fx": 1}}',
                        '400 digits'),
        'digits.toml': ('[cam]\nsize = [' + '9' * 400 + ', 1]', 'digits'),
        'digits.yaml': ('cameras:\n  a:\n    image_width: ' + '9' * 400, '400 digits'),
        'inf.json': ('{"0": {"R": [1e400], "T": [0, 0, 0], "fx": 1}}', 'out of range'),
    }
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    for name, (text, match) in cases.items():
        path = write(tmp_path, name, text)
        t0 = time.process_time()
        with pytest.raises(CalibrationError) as info:
            load_calibration(path)
        assert path in str(info.value) and match in str(info.value), str(info.value)
        assert time.process_time() - t0 < 5.0, name   # generous: it takes milliseconds
    # the bomb expands to 4e9 nodes; refusing it must not allocate them (was 2.9 GB)
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - rss0 < 200_000   # kB
