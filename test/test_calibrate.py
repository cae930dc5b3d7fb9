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
``mv3dpose calibrate`` on real detections (Pose2Sim: 2 people, 4 cameras, OpenPose BODY_25B).

Calibrated from its people only and compared with its Qualisys calibration, a bumped camera
found by ``--refine``, and each bad input's message.
"""

import os
import shutil

from mv3dpose_ros import cli
from mv3dpose_ros.core.calibration import load_calibration, save_rig_yaml
from mv3dpose_ros.core.camera import Camera
from mv3dpose_ros.core.selfcal import align_to, camera_errors
import numpy as np
import pytest

DATA = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), '..',
                    'shared', 'data', 'pose2sim_multiperson')
CALIB = os.path.join(DATA, 'Calib_qualisys.toml')
POSES = os.path.join(DATA, 'pose')
pytestmark = pytest.mark.skipif(not os.path.isdir(DATA), reason=f'no Pose2Sim data at {DATA}')


def _run(capsys, *argv):
    code = cli.main(['calibrate', *argv, '--no-picture'] if '--picture' not in argv
                    else ['calibrate', *[a for a in argv if a != '--picture']])
    out = capsys.readouterr()
    return code, out.out, out.err


def _copy(tmp_path, frames, edit=None):
    """Copy the Pose2Sim pose folders (only ``frames``), optionally editing the files."""
    root = tmp_path / 'pose'
    for cam in sorted(os.listdir(POSES)):
        os.makedirs(root / cam)
        files = sorted(os.listdir(os.path.join(POSES, cam)))
        for k in frames:
            src = os.path.join(POSES, cam, files[k])
            dst = root / cam / files[k]
            if edit is None:
                shutil.copy(src, dst)
            else:
                edit(cam, k, src, dst)
    return str(root)


def test_pose2sim_from_people_only(tmp_path, capsys):
    out = str(tmp_path / 'rig.yaml')
    code, text, err = _run(capsys, '--calibration', CALIB, '--poses', POSES, '--layout',
                           'body25b', '-o', out, '--picture')
    assert code == 0, err
    est, ref = load_calibration(out), load_calibration(CALIB)
    assert sorted(est) == sorted(ref)
    # the extrinsics come from the people: the Qualisys ones are not simply copied
    assert max(np.abs(est[n].t - ref[n].t).max() for n in ref) > 0.1
    aligned, _ = align_to(est, ref, robust=False)
    err_by_cam = camera_errors(aligned, ref)
    for name, (deg, metres) in err_by_cam.items():
        assert deg < 1.5 and metres < 0.12, (name, deg, metres)
    assert np.mean([e[0] for e in err_by_cam.values()]) < 1.0
    # world frame: z up (cameras above the floor), people near the origin
    assert all(c.center[2] > 0.3 for c in est.values())
    assert 'cam_01' in text and 'person matches' in text and 'world frame' in text
    assert os.path.isfile(str(tmp_path / 'rig.report.txt'))
    assert os.path.getsize(str(tmp_path / 'rig.png')) > 1000


def _bump(cam: Camera, deg: float, metres: float) -> Camera:
    axis = np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2])
    a = np.radians(deg)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    dR = np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K
    R_wc = cam.R_world_cam @ dR
    centre = cam.center + metres * np.array([1.0, 0.0, 0.0])
    return Camera.from_pose(cam.name, cam.K, cam.dist, R_wc, centre, cam.width, cam.height)


@pytest.mark.xfail(strict=True, reason='known gap: on real Pose2Sim detections the adjustment '
                   'moves every camera ~0.4-0.9 deg / 3-8 cm towards the detections, and the '
                   'bumped one only 2 deg / 3 cm (see docs/calibrate.md, Limits)')
def test_refine_finds_and_corrects_a_bumped_camera(tmp_path, capsys):
    ref = load_calibration(CALIB)
    bumped = dict(ref)
    bumped['cam_03'] = _bump(ref['cam_03'], 3.0, 0.10)
    given = str(tmp_path / 'bumped.yaml')
    save_rig_yaml(bumped, given)
    out = str(tmp_path / 'refined.yaml')
    code, text, err = _run(capsys, '--calibration', given, '--poses', POSES, '--layout',
                           'body25b', '-o', out, '--refine', '--max-frames', '50')
    assert code == 0, err
    est = load_calibration(out)
    moved = camera_errors(est, bumped)
    assert moved['cam_03'][0] > 2.0 and moved['cam_03'][1] > 0.05, moved
    for name in ('cam_01', 'cam_02', 'cam_04'):
        assert moved[name][0] < 1.0 and moved[name][1] < 0.05, (name, moved)
    fixed = camera_errors(est, ref)['cam_03']
    assert fixed[0] < 1.0 and fixed[1] < 0.05, fixed
    assert 'moved deg' in text


def test_too_few_frames(tmp_path, capsys):
    root = _copy(tmp_path, range(4))
    code, _, err = _run(capsys, '--calibration', CALIB, '--poses', root, '--layout',
                        'body25b', '-o', str(tmp_path / 'rig.yaml'))
    assert code == 2 and 'too few frames' in err and 'Traceback' not in err
    assert not os.path.exists(tmp_path / 'rig.yaml')


def test_people_standing_still(tmp_path, capsys):
    def same_frame(cam, k, src, dst):      # every file is the first frame: nobody moves
        shutil.copy(os.path.join(os.path.dirname(src), sorted(os.listdir(
            os.path.dirname(src)))[0]), dst)
    root = _copy(tmp_path, range(30), same_frame)
    code, _, err = _run(capsys, '--calibration', CALIB, '--poses', root, '--layout',
                        'body25b', '-o', str(tmp_path / 'rig.yaml'))
    assert code == 2 and 'degenerate motion' in err, err


def test_intrinsics_missing_for_a_camera(tmp_path, capsys):
    root = _copy(tmp_path, range(12))
    shutil.copytree(os.path.join(root, 'cam04_json'), os.path.join(root, 'cam09_json'))
    code, _, err = _run(capsys, '--calibration', CALIB, '--poses', root, '--layout',
                        'body25b', '-o', str(tmp_path / 'rig.yaml'))
    assert code == 2 and 'intrinsics missing' in err and 'cam09_json' in err, err


@pytest.mark.xfail(strict=True, reason='known gap: with 2 people, chance epipolar agreement of '
                   'shuffled frames still gives 52-85 person matches, so the camera is placed')
def test_camera_that_never_shares_a_person(tmp_path, capsys):
    def shuffled(cam, k, src, dst):        # cam_04 sees other instants than the rest
        if cam == 'cam04_json':
            files = sorted(os.listdir(os.path.dirname(src)))
            src = os.path.join(os.path.dirname(src), files[(k * 37 + 50) % len(files)])
        shutil.copy(src, dst)
    root = _copy(tmp_path, range(0, 100, 2), shuffled)
    out = str(tmp_path / 'rig.yaml')
    code, text, err = _run(capsys, '--calibration', CALIB, '--poses', root, '--layout',
                           'body25b', '-o', out)
    assert code == 3, err
    assert sorted(load_calibration(out)) == ['cam_01', 'cam_02', 'cam_03']
    assert 'cam_04' in text and 'never shares a person' in text
