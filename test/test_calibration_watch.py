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
The calibration watch in the live loop: a turned camera is named, left out, corrected.

Runs ``LiveFusion.step_set`` (the path of ``mv3dpose track --smooth causal`` and, set by set,
of ``fusion_node``) on simulated rigs and on the Pose2Sim real detections, with one camera's
keypoints moved exactly as a rotation of that camera about its centre moves them.
"""

import glob
import os

from mv3dpose_ros.core.fusion.pipeline import FusionConfig
from mv3dpose_ros.core.geometry.calibration import load_calibration
from mv3dpose_ros.core.geometry.camera import turn_keypoints, turned
from mv3dpose_ros.core.live.loop import LiveFusion, LiveLog
from mv3dpose_ros.core.live.sync import SyncConfig
from mv3dpose_ros.core.selfcal.watch import (robust_rotation, rotation_angle_deg,
                                             WatchConfig)
from mv3dpose_ros.core.types import NS_PER_S
from mv3dpose_ros.io.openpose import read_openpose_file
from mv3dpose_ros.sim import make_scene
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

P2S = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..', '..', 'shared', 'data',
                   'pose2sim_multiperson')


def turn(deg: float, axis=(0.3, 1.0, 0.2)) -> np.ndarray:
    """Return the rotation of ``deg`` degrees about ``axis`` (a camera's own frame)."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    return Rotation.from_rotvec(np.radians(deg) * axis).as_matrix()


class Run:
    """One ``LiveFusion`` over a sequence, one camera turned from a frame on; what it said."""

    def __init__(self, cameras, layout, views, fps, mode='correct', bumped=None, deg=0.0,
                 bump_at=0, drop=0.0, unbump_at=None, seed=0):
        self.warnings, self.infos, self.rigs = [], [], []
        log = LiveLog(info=self.infos.append, warning=self.warnings.append,
                      throttled=lambda key, text: self.warnings.append(text),
                      rig=lambda cams: self.rigs.append(dict(cams)))
        self.live = LiveFusion(list(cameras), layout, SyncConfig(), FusionConfig(), log=log,
                               watch_config=WatchConfig(mode=mode))
        self.live.start(cameras)
        self.rotation = turn(deg)
        self.named_at = self.excluded = None
        rng = np.random.default_rng(seed)
        for f, frame in enumerate(views):
            frame = dict(frame)
            if bumped and f >= bump_at and (unbump_at is None or f < unbump_at) and \
                    len(frame[bumped]):
                poses = frame[bumped].copy()
                poses[..., :2] = turn_keypoints(cameras[bumped], poses[..., :2],
                                                self.rotation)
                frame[bumped] = poses
            if drop:
                frame = {c: p for c, p in frame.items() if rng.random() >= drop}
            before = len(self.warnings)
            self.live.step_set(frame, int(round(f * NS_PER_S / fps)))
            if self.named_at is None and any('disagrees' in w for w in
                                             self.warnings[before:]):
                self.named_at = f
                self.excluded = self.live.watch.excluded()


def sim(cameras=5, frames=300, seed=2):
    return make_scene(num_cameras=cameras, num_people=3, num_frames=frames, fps=25, seed=seed)


def test_robust_rotation_recovers_a_turn_through_outliers():
    rng = np.random.default_rng(0)
    predicted = rng.normal(size=(300, 3)) + [0, 0, 4]
    predicted /= np.linalg.norm(predicted, axis=1, keepdims=True)
    truth = turn(1.5)
    observed = predicted @ truth.T + rng.normal(scale=2e-3, size=predicted.shape)
    observed[:60] = rng.normal(size=(60, 3))            # a fifth matched to nobody
    observed /= np.linalg.norm(observed, axis=1, keepdims=True)
    estimate = robust_rotation(observed, predicted, np.ones(300))
    assert rotation_angle_deg(estimate @ truth.T) < 0.05


def test_turned_keypoints_are_what_the_turned_camera_sees():
    scene = sim(frames=2)
    cam = scene.cameras['cam_02']
    rotation = turn(3.0)
    points = scene.gt[0].reshape(-1, 3)
    seen = turn_keypoints(cam, cam.project(points), rotation)
    assert np.nanmax(np.abs(seen - turned(cam, rotation).project(points))) < 1e-6


def test_a_turned_camera_is_named_within_two_seconds_and_corrected():
    scene = sim()
    run = Run(scene.cameras, scene.layout, scene.views, 25, bumped='cam_02', deg=2.0,
              bump_at=125)
    named = [w for w in run.warnings if 'disagrees' in w]
    assert len(named) == 1 and "camera 'cam_02'" in named[0], run.warnings
    assert 0 < run.named_at - 125 <= 50                       # within 2 s at 25 fps
    assert run.excluded == ['cam_02']                        # left out while estimated
    assert 'found at the set stamped' in named[0] and 'deg' in named[0]
    assert any("camera 'cam_02' corrected" in w for w in run.warnings)
    truth = turned(scene.cameras['cam_02'], run.rotation)
    assert rotation_angle_deg(run.live.cameras['cam_02'].R @ truth.R.T) < 0.2
    assert run.rigs and run.rigs[-1]['cam_02'] is run.live.cameras['cam_02']
    for name in ('cam_01', 'cam_03', 'cam_04', 'cam_05'):         # the majority held
        assert run.live.cameras[name] is scene.cameras[name]
    assert run.live.watch.excluded() == []                    # back in the rig
    status = run.live.watch.status['cam_02']
    assert status.level == 'OK' and status.corrections == 1


@pytest.mark.parametrize('drop', [0.0, 0.4])
def test_no_camera_is_named_without_a_turn(drop):
    scene = sim(frames=400)             # dropped views: the baselines take longer
    run = Run(scene.cameras, scene.layout, scene.views, 25, drop=drop)
    assert not [w for w in run.warnings if 'disagrees' in w]
    assert not run.rigs
    assert all(s.level == 'OK' for s in run.live.watch.status.values())
    assert all(np.isfinite(s.drift_deg) for s in run.live.watch.status.values())


def test_exclude_mode_leaves_the_camera_out_until_it_agrees_again():
    scene = sim(frames=350)
    run = Run(scene.cameras, scene.layout, scene.views, 25, mode='exclude', bumped='cam_03',
              deg=3.0, bump_at=125, unbump_at=225)
    assert run.excluded == ['cam_03'] and run.named_at < 225
    assert any("camera 'cam_03' agrees with the rig again" in i for i in run.infos)
    assert run.live.watch.excluded() == [] and not run.rigs
    assert run.live.cameras['cam_03'] is scene.cameras['cam_03']   # never changed


def test_warn_mode_names_but_changes_nothing():
    scene = sim(frames=250)
    run = Run(scene.cameras, scene.layout, scene.views, 25, mode='warn', bumped='cam_02',
              deg=2.0, bump_at=125)
    named = [w for w in run.warnings if 'disagrees' in w]
    assert len(named) == 1 and 'mv3dpose calibrate --refine' in named[0]
    assert run.excluded == [] and not run.rigs


def test_three_cameras_name_the_camera_but_do_not_correct_it():
    scene = sim(cameras=3, frames=250)
    run = Run(scene.cameras, scene.layout, scene.views, 25, bumped='cam_02', deg=2.0,
              bump_at=125)
    named = [w for w in run.warnings if 'disagrees' in w]
    assert len(named) == 1 and "camera 'cam_02'" in named[0]
    assert 'only 2 other camera(s) agree' in named[0]
    assert not run.rigs and run.live.cameras['cam_02'] is scene.cameras['cam_02']


def _pose2sim_ping_pong(loops: int = 3):
    """Return the Pose2Sim rig and its real detections played forwards and back ``loops`` times."""
    cams = load_calibration(os.path.join(P2S, 'Calib_qualisys.toml'))
    dirs = sorted(glob.glob(os.path.join(P2S, 'pose', '*')))
    files = [sorted(glob.glob(os.path.join(d, '*.json'))) for d in dirs]
    frames = [{n: read_openpose_file(files[i][k]) for i, n in enumerate(cams)}
              for k in range(len(files[0]))]
    return cams, (frames + frames[::-1][1:-1]) * loops


@pytest.mark.skipif(not os.path.isdir(P2S), reason='needs ../shared/data/pose2sim_multiperson')
def test_real_detections_a_turned_camera_is_named_and_corrected_and_none_without():
    cams, frames = _pose2sim_ping_pong()
    clean = Run(cams, 'body25b', frames, 60)
    assert not [w for w in clean.warnings if 'disagrees' in w]
    run = Run(cams, 'body25b', frames, 60, bumped='cam_02', deg=2.0, bump_at=300)
    named = [w for w in run.warnings if 'disagrees' in w]
    assert named and "camera 'cam_02'" in named[0]
    assert 0 < run.named_at - 300 <= 120                      # within 2 s at 60 fps
    truth = turned(cams['cam_02'], run.rotation)
    assert rotation_angle_deg(run.live.cameras['cam_02'].R @ truth.R.T) < 0.3
