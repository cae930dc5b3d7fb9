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

"""The Fusion pipeline end to end on synthetic scenes, plus its contract and edge cases."""

import logging

from mv3dpose_ros.core.fusion.pipeline import Fusion, FusionConfig
from mv3dpose_ros.core.types import JointState, Track, TrackState
from mv3dpose_ros.eval.mot import MOTEvaluator
from mv3dpose_ros.sim.detector import DetectorNoise
from mv3dpose_ros.sim.scene import make_scene
import numpy as np
import pytest


def _run(scene, config=None):
    fusion = Fusion(scene.cameras, scene.layout, config)
    return fusion, [fusion.step(views, stamp) for stamp, views in scene.frames()]


def _mot(scene, outputs):
    ev = MOTEvaluator(threshold_m=0.5)
    for t, out in enumerate(outputs):
        hyp = [tr for tr in out if tr.state in (TrackState.CONFIRMED, TrackState.COASTING)]
        ev.update(range(scene.num_people), scene.gt[t], [tr.track_id for tr in hyp],
                  np.array([tr.joints for tr in hyp]).reshape(len(hyp), scene.gt.shape[2], 3))
    return ev.result()


@pytest.mark.parametrize('cams, people, seed', [(4, 3, 0), (3, 4, 1), (6, 5, 2)])
def test_moderate_noise_scene_is_tracked(cams, people, seed):
    scene = make_scene(num_cameras=cams, num_people=people, num_frames=80, seed=seed)
    _, outputs = _run(scene)
    r = _mot(scene, outputs)
    assert r.mota >= 0.95, r.summary()
    assert r.id_switches == 0 and r.motp_m < 0.05, r.summary()


def test_two_cameras_and_heavy_noise():
    scene = make_scene(num_cameras=2, num_people=2, num_frames=60, seed=3)
    r = _mot(scene, _run(scene)[1])
    assert r.mota >= 0.95 and r.id_switches == 0, r.summary()
    noisy = make_scene(num_cameras=5, num_people=4, num_frames=60, seed=4,
                       noise=DetectorNoise().scaled(2.5))
    r = _mot(noisy, _run(noisy)[1])
    assert r.mota >= 0.9 and r.id_switches == 0, r.summary()


def test_output_contract():
    scene = make_scene(num_cameras=4, num_people=2, num_frames=12, seed=5)
    fusion, outputs = _run(scene)
    lay = fusion.layout
    hips = list(lay.root_joints)
    for out in outputs:
        assert [t.track_id for t in out] == sorted(t.track_id for t in out)
        for t in out:
            assert isinstance(t, Track) and t.track_id >= 1
            missing = t.joint_state == JointState.MISSING
            assert np.isnan(t.joints[missing]).all() and np.isfinite(t.joints[~missing]).all()
            assert (t.confidence[missing] == 0).all()
            assert ((t.confidence >= 0) & (t.confidence <= 1)).all()
            assert t.joints.shape == (lay.num_joints, 3) and t.num_views.dtype == np.uint8
            if np.isfinite(t.joints[hips]).all():
                assert t.position == pytest.approx(t.joints[hips].mean(axis=0))
            seen = t.joint_state == JointState.TRIANGULATED
            assert (t.num_views[seen] >= 2).all() and np.isfinite(t.reprojection_error[seen]).all()
            assert set(t.source_cameras) <= set(scene.cameras)
    last = outputs[-1]
    assert {t.state for t in last} == {TrackState.CONFIRMED}
    assert all(t.age == 12 and t.first_seen == scene.stamps[0] for t in last)
    # the causal filter tracks the ground truth closely
    err = np.nanmean([np.nanmean(np.linalg.norm(t.joints - scene.gt[-1], axis=-1), axis=1).min()
                      for t in last])
    assert err < 0.05
    # last_poses / last_members describe the final step
    assert fusion.last_members.shape == (len(fusion.last_poses), 4)
    assert fusion.last_info['poses_3d'] == len(fusion.last_poses)


def test_deleted_tombstones_reset_and_time_going_back(caplog):
    scene = make_scene(num_cameras=3, num_people=2, num_frames=10, seed=6)
    cfg = FusionConfig(max_coast_s=0.2)
    fusion, outputs = _run(scene, cfg)
    ids = {t.track_id for t in outputs[-1]}
    t_end = scene.stamps[-1]
    empty = {name: np.zeros((0, 17, 3)) for name in scene.cameras}
    out = fusion.step(empty, t_end + 0.1)
    assert {t.state for t in out} == {TrackState.COASTING}
    out = fusion.step(empty, t_end + 0.35)
    assert {t.track_id for t in out} == ids and {t.state for t in out} == {TrackState.DELETED}
    assert all(np.isnan(t.joints).all() and t.score == 0 for t in out)
    assert fusion.step(empty, t_end + 0.4) == []               # each tombstone only once
    for stamp, views in list(scene.frames())[:3]:
        out = fusion.step(views, t_end + 1 + stamp)
    assert min(t.track_id for t in out) > max(ids)             # ids never reused
    live = {t.track_id for t in out}
    tombs = fusion.reset()
    assert {t.track_id for t in tombs} == live
    with caplog.at_level(logging.WARNING):
        before = {t.track_id for t in fusion.step(scene.views[0], t_end + 2)}
        out = fusion.step(scene.views[0], 0.0)                 # time went back: reset
    assert {t.track_id for t in out if t.state == TrackState.DELETED} == before
    assert all(t.track_id > max(before) for t in out if t.state != TrackState.DELETED)
    assert 'stamp went back' in caplog.text


def test_bad_views_are_skipped_not_fatal(caplog):
    scene = make_scene(num_cameras=3, num_people=1, num_frames=4, seed=7)
    fusion = Fusion(scene.cameras, scene.layout)
    names = list(scene.cameras)
    with caplog.at_level(logging.WARNING):
        for stamp, views in scene.frames():
            views = dict(views)
            views['no_such_camera'] = views[names[0]]
            views[names[1]] = np.zeros((1, 5, 3))              # wrong joint count
            out = fusion.step(views, stamp)
    assert 'no_such_camera' in caplog.text and names[1] in caplog.text
    assert len(out) == 1                                       # two good views remain
    # empty, absent, all-missing and NaN inputs
    nan_pose = np.full((1, 17, 3), np.nan)
    zero_pose = np.zeros((2, 17, 3))
    fusion.step({}, 10.0)
    fusion.step({names[0]: nan_pose, names[1]: zero_pose, names[2]: np.zeros((0,))}, 10.1)
    fusion.step({names[0]: [], names[1]: np.zeros((0, 17, 3))}, 10.2)


def test_config_validation_names_the_field():
    with pytest.raises(ValueError, match='epipolar_threshold_norm'):
        FusionConfig(epipolar_threshold_norm=0).validate()
    with pytest.raises(ValueError, match='smoothing'):
        FusionConfig(smoothing='gaussian').validate()
    with pytest.raises(ValueError, match='min_views'):
        FusionConfig(min_views=1).validate()
    scene = make_scene(num_cameras=2, num_people=1, num_frames=1, seed=8)
    one = dict(list(scene.cameras.items())[:1])
    with pytest.raises(ValueError, match='at least two cameras'):
        Fusion(one, 'coco17')
    with pytest.raises(ValueError, match='unknown skeleton layout'):
        Fusion(scene.cameras, 'mpii16')


def test_without_smoothing_outputs_raw_triangulations():
    scene = make_scene(num_cameras=4, num_people=2, num_frames=6, seed=9)
    fusion, outputs = _run(scene, FusionConfig(smoothing='none'))
    last = outputs[-1]
    for t in last:
        k = np.argmin(np.nanmean(np.linalg.norm(fusion.last_poses - t.joints, axis=-1), 1))
        assert np.array_equal(np.isnan(t.joints), np.isnan(fusion.last_poses[k]))
        assert np.allclose(t.joints, fusion.last_poses[k], equal_nan=True)


def test_same_inputs_same_outputs():
    scene = make_scene(num_cameras=3, num_people=3, num_frames=15, seed=10)
    a = _run(scene)[1]
    b = _run(scene)[1]
    for fa, fb in zip(a, b):
        assert [t.track_id for t in fa] == [t.track_id for t in fb]
        for ta, tb in zip(fa, fb):
            assert np.array_equal(ta.joints, tb.joints, equal_nan=True)


def test_uncertainty_is_honest_and_follows_the_detector_noise():
    errors, variances, noise = {}, {}, {}
    for scale in (1.0, 2.0):
        scene = make_scene(num_cameras=4, num_people=3, num_frames=80, seed=6,
                           noise=DetectorNoise().scaled(scale))
        fusion, outputs = _run(scene)
        noise[scale] = fusion.noise_norm
        err, var = [], []
        for t, out in enumerate(outputs[20:], 20):
            for tr in out:
                if tr.state != TrackState.CONFIRMED:
                    continue
                ok = tr.joint_state == JointState.TRIANGULATED
                assert (tr.joint_variance[ok] > 0).all()        # finite and positive
                assert np.isnan(tr.joint_variance[tr.joint_state == JointState.MISSING]).all()
                cov = tr.position_covariance
                assert np.isfinite(cov).all() and cov[0, 0] > 0 and np.allclose(cov, cov.T)
                d = np.linalg.norm(scene.gt[t] - tr.joints[None], axis=-1)          # [M, J]
                who = int(np.argmin(np.nanmean(d, axis=1)))
                err.extend((tr.joints[ok] - scene.gt[t][who][ok]).ravel())
                var.extend(np.repeat(tr.joint_variance[ok], 3))
        errors[scale], variances[scale] = np.array(err), np.array(var)
    # the estimated 2D noise follows the detector, and so does the reported variance
    assert 1.6 < noise[2.0] / noise[1.0] < 2.5
    assert np.median(variances[2.0]) > 2 * np.median(variances[1.0])
    for scale in (1.0, 2.0):        # per-axis error spread close to the claimed variance
        ratio = np.std(errors[scale]) / np.sqrt(np.mean(variances[scale]))
        assert 0.6 < ratio < 1.5, (scale, ratio)


def test_stamps_are_exact_nanoseconds():
    scene = make_scene(num_cameras=3, num_people=2, num_frames=10, seed=1)
    fusion = Fusion(scene.cameras, scene.layout)
    base = 1_796_000_000_123_456_789          # beyond what float seconds hold to the ns
    for k, (stamp, views) in enumerate(scene.frames()):
        out = fusion.step(views, base / 1e9 + stamp, base + k * 40_000_001)
    for tr in out:
        assert tr.last_observed_ns == base + 9 * 40_000_001
        assert tr.first_seen_ns == base
