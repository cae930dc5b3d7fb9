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
Fusion on real multi-view data from ../shared/data (skipped when it is absent).

- Pose2Sim: real OpenPose BODY_25B detections of 4 cameras, 100 frames at 60 fps.
- Campus: 3D ground truth projected into the 3 cameras with detector-like noise, PCP.
- Panoptic 160906_band1: 3D ground truth projected into 5 HD cameras, tracks and MPJPE.

Run with ``-s`` to see the measured figures.
"""

import os

from mv3dpose_ros.core.fusion.pipeline import Fusion
from mv3dpose_ros.core.geometry.calibration import load_calibration
from mv3dpose_ros.core.types import TrackState
from mv3dpose_ros.eval.mpjpe import mpjpe
from mv3dpose_ros.eval.pcp import evaluate_pcp
from mv3dpose_ros.io.datasets import CAMPUS_TEST_FRAMES, load_campus_gt, load_panoptic_gt
from mv3dpose_ros.io.openpose import match_camera_folders, OpenPoseSequence
import numpy as np


def _noisy_views(cameras, joints, rng, noise_px=3.0, miss=0.05, outliers=0.01):
    """
    Project world joints ``[P, J, 3]`` like a detector would see them.

    Gaussian pixel noise, missed joints, rare gross outliers (30 px), confidences in
    [0.4, 1], joints outside the image dropped, poses with fewer than 4 joints dropped,
    detection order shuffled.
    """
    views = {}
    for name, cam in cameras.items():
        uv = cam.project(joints)
        inside = cam.in_image(uv)
        uv = uv + rng.normal(0.0, noise_px, uv.shape)
        wild = rng.random(uv.shape[:2]) < outliers
        uv[wild] += rng.choice([-30.0, 30.0], size=(int(wild.sum()), 2))
        conf = rng.uniform(0.4, 1.0, uv.shape[:2])
        conf[(rng.random(conf.shape) < miss) | ~inside] = 0.0
        arr = np.concatenate([np.nan_to_num(uv), conf[..., None]], axis=-1)
        arr = arr[(conf > 0).sum(axis=1) >= 4]
        views[name] = arr[rng.permutation(len(arr))]
    return views


def _confirmed_ids(out):
    return {t.track_id for t in out if t.state in (TrackState.CONFIRMED, TrackState.COASTING)}


def test_pose2sim_openpose_two_persistent_tracks(shared_data):
    root = os.path.join(shared_data, 'pose2sim_multiperson')
    cameras = load_calibration(os.path.join(root, 'Calib_qualisys.toml'))
    folders, missing = match_camera_folders(os.path.join(root, 'pose'), list(cameras))
    assert not missing
    seq = OpenPoseSequence(folders, num_joints=25)
    fusion = Fusion(cameras, 'body25b')
    per_frame, errors, first, last = [], [], {}, {}
    for i, (frame, views) in enumerate(seq):
        out = fusion.step(views, frame / 60.0)
        ids = _confirmed_ids(out)
        per_frame.append(ids)
        for k in ids:
            first.setdefault(k, i)
            last[k] = i
        for t in out:
            if t.track_id in ids:
                errors.extend(t.reprojection_error[np.isfinite(t.reprojection_error)])
    assert len(per_frame) == 100
    ever = set().union(*per_frame)
    median_px = float(np.median(errors))
    print(f'\nPose2Sim: confirmed track ids {sorted(ever)}, frames {first} .. {last}, '
          f'median reprojection error {median_px:.1f} px over {len(errors)} joints')
    assert len(ever) == 2, f'expected two people, got tracks {sorted(ever)}'
    # persistent: confirmed from the third frame on, never lost, so no id switch
    assert all(first[k] <= 2 and last[k] == 99 for k in ever)
    assert all(ids == ever for ids in per_frame[3:])
    assert median_px < 20.0


def test_campus_projected_ground_truth_pcp(shared_data):
    root = os.path.join(shared_data, 'campus')
    cameras = load_calibration(os.path.join(root, 'calibration_campus.json'))
    gt = load_campus_gt(os.path.join(root, 'actorsGT.mat'))
    rng = np.random.default_rng(0)
    fusion = Fusion(cameras, 'shelf14')
    frames = []
    for f in CAMPUS_TEST_FRAMES:
        truth = gt.frame(f)
        annotated = np.isfinite(truth).all(axis=(1, 2))
        out = fusion.step(_noisy_views(cameras, truth[annotated], rng), f / 25.0)
        pred = np.array([t.joints for t in out if t.state != TrackState.DELETED])
        frames.append((pred.reshape(-1, 14, 3),
                       {a: truth[a] for a in range(len(truth)) if annotated[a]}))
    result = evaluate_pcp(frames)
    print('\nCampus, GT projected with 3 px noise, 5 % missed joints, 1 % outliers:\n'
          + result.table())
    assert result.average >= 0.97
    assert result.recall >= 0.97


def test_panoptic_projected_ground_truth_tracks_and_mpjpe(shared_data):
    root = os.path.join(shared_data, 'panoptic_160906_band1')
    every = load_calibration(os.path.join(root, 'calibration_160906_band1.json'))
    names = ('00_03', '00_06', '00_12', '00_13', '00_23')
    cameras = {n: every[n] for n in names}
    gt = load_panoptic_gt(os.path.join(root, 'hdPose3d_stage1_coco19'))
    body_ids, poses = gt.as_array()
    rng = np.random.default_rng(1)
    fusion = Fusion(cameras, 'panoptic19')
    owner = {}
    pairs = []
    for i, frame in enumerate(gt.frames):
        truth = poses[i, :, :, :3]
        out = fusion.step(_noisy_views(cameras, truth, rng), frame / 30.0)
        live = [t for t in out if t.state != TrackState.DELETED]
        for t in live:
            d = np.nanmean(np.linalg.norm(truth - t.joints[None], axis=-1), axis=1)
            owner.setdefault(t.track_id, set()).add(int(body_ids[np.nanargmin(d)]))
        pairs.append((np.array([t.joints for t in live]).reshape(-1, 19, 3), truth))
    result = mpjpe(pairs)
    print(f'\nPanoptic band1, 5 HD cameras, GT projected with 3 px noise: {len(owner)} tracks '
          f'{owner}, MPJPE {1000 * result.mpjpe_m:.1f} mm, recall {result.recall:.2f}')
    assert len(owner) == 3
    assert all(len(v) == 1 for v in owner.values())            # no id switch
    assert sorted(b for v in owner.values() for b in v) == sorted(body_ids.tolist())
    assert result.recall == 1.0 and result.mpjpe_m < 0.03
