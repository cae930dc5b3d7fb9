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
``mv3dpose calibrate`` on real detections and on a Shelf-like proxy.

Pose2Sim (2 people, 4 cameras, real OpenPose BODY_25B): calibrated from its people only and
compared with its Qualisys calibration, a bumped camera found by ``--refine``, and each bad
input's message. Shelf proxy (the Shelf rig, 4 people milling about its shelf, seen through a
real detector's errors): the rig from the 2D detections only, and tracking with it scored
against tracking with the true rig.
"""

import os
import shutil

from mv3dpose_ros import cli
from mv3dpose_ros.core.fusion.pipeline import Fusion
from mv3dpose_ros.core.geometry.calibration import load_calibration, save_rig_yaml
from mv3dpose_ros.core.geometry.camera import Camera
from mv3dpose_ros.core.live.output import LiveOutput
from mv3dpose_ros.core.selfcal.extrinsics import calibrate
from mv3dpose_ros.core.selfcal.frame import align_to, camera_errors
from mv3dpose_ros.core.selfcal.views import normalise_views
from mv3dpose_ros.core.types import TrackState
from mv3dpose_ros.eval.sequence import evaluate_run, GroundTruth
from mv3dpose_ros.sim.detector import detect, DetectorNoise
from mv3dpose_ros.sim.people import simulate_people, WalkConfig
import numpy as np
import pytest

SHARED = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), '..',
                      'shared', 'data')
DATA = os.path.join(SHARED, 'pose2sim_multiperson')
CALIB = os.path.join(DATA, 'Calib_qualisys.toml')
POSES = os.path.join(DATA, 'pose')
SHELF = os.path.join(SHARED, 'shelf', 'calibration_shelf.json')
needs_p2s = pytest.mark.skipif(not os.path.isdir(DATA), reason=f'no Pose2Sim data at {DATA}')
needs_shelf = pytest.mark.skipif(not os.path.isfile(SHELF), reason=f'no Shelf rig at {SHELF}')

#: A real detector's errors on Shelf-like images (people 300-500 px tall): 3 px + 1 % of the
#: height of noise, 5 % missed joints and people, a false person every 10 frames per camera,
#: 3 % left/right swaps, 2 % joints 60 px off. (No view-dependent joint bias: real detectors
#: have some, Pose2Sim's figures show its size.)
REAL_DETECTOR = DetectorNoise(pixel_noise_px=3.0, relative_noise=0.01, joint_miss_rate=0.05,
                              person_miss_rate=0.05, false_positive_rate=0.1, swap_rate=0.03,
                              outlier_rate=0.02, outlier_px=60.0)


def shelf_proxy(frames: int, people: int = 4, seed: int = 1):
    """
    Return ``(cameras, gt [T, M, 17, 3], views)``: the Shelf rig, people milling about its shelf.

    The people walk slowly (0.3-1 m/s) in a 1.4 m radius around the point the five cameras
    look at, COCO-17 joints, 25 fps, seen through ``REAL_DETECTOR``.
    """
    cams = load_calibration(SHELF)
    walk = WalkConfig(area_radius_m=1.4, center=(0.45, -0.3), speed_range_mps=(0.3, 1.0),
                      min_separation_m=0.6)
    gt, _, _ = simulate_people(people, frames, 25.0, 'coco17', walk, None,
                               np.random.default_rng(seed))
    views, _ = detect(cams, gt, 'coco17', REAL_DETECTOR, seed=seed + 1)
    return cams, gt, views


def self_calibrate(cams: dict, views: list, layout: str, every: int = 1, **kw):
    """Calibrate ``cams``' extrinsics from the detections ``views`` (every ``every``-th frame)."""
    sv = normalise_views(((k, v) for k, v in enumerate(views[::every])), cams, layout)
    return calibrate(sv, cams, layout, **kw)


def track_score(cams: dict, layout: str, views: list, gt, fps: float, frames=None):
    """Track ``views`` (Fusion + the live output) and score: ``(PCP %, MPJPE mm)``."""
    fusion = Fusion(cams, layout)
    output = LiveOutput(fusion.config.publish_coast_s)
    num = fusion.layout.num_joints
    hyps = {}
    for f, v in enumerate(views):
        tracks = [t for t in output.step(fusion.step(v, f / fps), f / fps)[0]
                  if t.state in (TrackState.CONFIRMED, TrackState.COASTING)]
        hyps[f] = (np.array([t.track_id for t in tracks], dtype=int),
                   np.array([t.joints for t in tracks]).reshape(len(tracks), num, 3))
    rep = evaluate_run(layout, hyps, gt, frames=frames)
    return 100 * rep.pcp.average, 1000 * rep.mpjpe.mpjpe_m


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


@needs_shelf
def test_shelf_proxy_tracks_as_well_with_the_estimated_rig():
    cams, gt, views = shelf_proxy(80)
    res = self_calibrate(cams, views, 'coco17')
    assert sorted(res.cameras) == sorted(cams) and not res.unplaced
    # the estimated rig in the true one's frame (a similarity on centres and orientations)
    aligned, _ = align_to(res.cameras, cams, robust=False)
    for name, (deg, metres) in camera_errors(aligned, cams).items():
        assert deg < 0.5 and metres < 0.05, (name, deg, metres)
    ids = np.arange(gt.shape[1])
    truth = GroundTruth('coco17', {f: (ids, gt[f]) for f in range(len(gt))})
    pcp_true, mm_true = track_score(cams, 'coco17', views, truth, 25.0, range(10, len(gt)))
    pcp_est, mm_est = track_score(aligned, 'coco17', views, truth, 25.0, range(10, len(gt)))
    assert pcp_est > pcp_true - 3.0, (pcp_est, pcp_true)
    assert mm_est < mm_true + 15.0, (mm_est, mm_true)


@needs_p2s
def test_pose2sim_from_people_only(tmp_path, capsys):
    out = str(tmp_path / 'rig.yaml')
    code, text, err = _run(capsys, '--calibration', CALIB, '--poses', POSES, '--layout',
                           'body25b', '-o', out, '--picture', '--frame', 'people')
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


@needs_shelf
def test_refine_finds_and_corrects_a_bumped_camera_in_the_shelf_proxy():
    cams, _, views = shelf_proxy(60, seed=3)
    bumped = dict(cams)
    bumped['2'] = _bump(cams['2'], 3.0, 0.10)
    res = self_calibrate(cams, views, 'coco17', initial=bumped)
    assert sorted(res.cameras) == sorted(cams) and not res.unplaced
    moved = camera_errors(res.cameras, bumped)
    assert moved['2'][0] > 2.5 and moved['2'][1] > 0.07, moved
    for name in ('0', '1', '3', '4'):        # the good cameras hold the frame
        assert moved[name][0] < 0.05 and moved[name][1] < 0.005, (name, moved)
    fixed = camera_errors(res.cameras, cams)['2']
    assert fixed[0] < 0.3 and fixed[1] < 0.03, fixed


@needs_p2s
@pytest.mark.xfail(strict=True, reason='known gap: on real Pose2Sim detections cam_03 is found '
                   '(moved ~2 deg / 5 cm) and the good cameras hold the frame, but fitted to the '
                   'detections it lands 1.0 deg / 12 cm off Qualisys: the detections disagree '
                   'with Qualisys (13 px median reprojection; see docs/calibrate.md, Limits)')
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


@needs_p2s
def test_too_few_frames(tmp_path, capsys):
    root = _copy(tmp_path, range(4))
    code, _, err = _run(capsys, '--calibration', CALIB, '--poses', root, '--layout',
                        'body25b', '-o', str(tmp_path / 'rig.yaml'))
    assert code == 2 and 'too few frames' in err and 'Traceback' not in err
    assert not os.path.exists(tmp_path / 'rig.yaml')


@needs_p2s
def test_people_standing_still(tmp_path, capsys):
    def same_frame(cam, k, src, dst):      # every file is the first frame: nobody moves
        shutil.copy(os.path.join(os.path.dirname(src), sorted(os.listdir(
            os.path.dirname(src)))[0]), dst)
    root = _copy(tmp_path, range(30), same_frame)
    code, _, err = _run(capsys, '--calibration', CALIB, '--poses', root, '--layout',
                        'body25b', '-o', str(tmp_path / 'rig.yaml'))
    assert code == 2 and 'degenerate motion' in err, err


@needs_p2s
def test_intrinsics_missing_for_a_camera(tmp_path, capsys):
    root = _copy(tmp_path, range(12))
    shutil.copytree(os.path.join(root, 'cam04_json'), os.path.join(root, 'cam09_json'))
    code, _, err = _run(capsys, '--calibration', CALIB, '--poses', root, '--layout',
                        'body25b', '-o', str(tmp_path / 'rig.yaml'))
    assert code == 2 and 'intrinsics missing' in err and 'cam09_json' in err, err


@needs_p2s
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


@needs_p2s
def test_pose2sim_keeps_the_frame_of_the_given_calibration(tmp_path, capsys):
    """By default the rig comes out in the given calibration's frame: no alignment needed."""
    out = str(tmp_path / 'rig.yaml')
    code, text, err = _run(capsys, '--calibration', CALIB, '--poses', POSES, '--layout',
                           'body25b', '-o', out, '--max-frames', '50')
    assert code == 0, err
    assert "world frame: the given calibration's" in text
    est, ref = load_calibration(out), load_calibration(CALIB)
    for name, (deg, metres) in camera_errors(est, ref).items():
        assert deg < 1.5 and metres < 0.12, (name, deg, metres)


@needs_shelf
def test_a_calibration_without_image_size_is_read_with_image_size_option(tmp_path, capsys):
    """Read a VoxelPose file (no image size) with ``--image-size WxH``; without, say so."""
    from mv3dpose_ros.io.openpose import openpose_filename, write_openpose_file

    rig = tmp_path / 'cams.json'                 # not named like a known data set
    shutil.copy(SHELF, rig)
    cams, _, views = shelf_proxy(40, people=2)
    for cam in cams:
        os.makedirs(tmp_path / 'pose' / cam)
        for k, frame in enumerate(views):
            write_openpose_file(str(tmp_path / 'pose' / cam / openpose_filename(cam, k)),
                                frame[cam])
    track = ['track', '--calibration', str(rig), '--poses', str(tmp_path / 'pose'),
             '--layout', 'coco17', '-o', str(tmp_path / 't.jsonl'), '--no-progress']
    assert cli.main(track) == 2
    assert '--image-size WxH' in capsys.readouterr().err
    assert cli.main(track + ['--image-size', '1032x776']) == 0
    capsys.readouterr()
    code, _, err = _run(capsys, '--calibration', str(rig), '--poses', str(tmp_path / 'pose'),
                        '--layout', 'coco17', '-o', str(tmp_path / 'r.yaml'))
    assert code == 2 and '--image-size WxH' in err
    code, _, err = _run(capsys, '--calibration', str(rig), '--image-size', '1032x776',
                        '--poses', str(tmp_path / 'pose'), '--layout', 'coco17',
                        '-o', str(tmp_path / 'r.yaml'))
    assert 'image size' not in err
