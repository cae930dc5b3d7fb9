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

"""Per-joint Kalman filters, fixed-lag smoothing, offline Gaussian smoothing with gaps."""

import dataclasses

from mv3dpose_ros.core.tracking.smoothing import (FixedLagSmoother, gaussian_smooth,
                                                  interpolate_gaps, JointKalman,
                                                  smooth_track_sequence)
from mv3dpose_ros.core.types import JointState, Track, TrackState
import numpy as np
import pytest

R = 0.01 ** 2          # measurement variance per axis [m^2] (1 cm)


def _update(f, z, stamp, r=R):
    z = np.asarray(z, dtype=float).reshape(len(f), -1, 3)
    return f.update(z, np.full(z.shape[:2], r), stamp)


def test_kalman_tracks_constant_velocity_without_lag():
    f = JointKalman(2, accel_noise=1.0, rows=1)
    for i in range(90):
        t = i / 30.0
        z = np.array([[1.2 * t, 0.0, 1.0], [0.0, -0.5 * t, 0.3]])
        out = _update(f, z, t)
    assert np.allclose(out.joints[0], z, atol=2e-3)
    assert (out.state == JointState.TRIANGULATED).all() and out.accepted.all()
    assert np.allclose(f.v[0], [[1.2, 0, 0], [0, -0.5, 0]], atol=0.02)
    assert (out.variance < R).all()                   # filtered beats one measurement


def test_kalman_velocity_starts_at_zero_not_from_two_noisy_samples():
    f = JointKalman(1, rows=1)
    _update(f, [0.0, 0.0, 0.0], 0.0)
    assert np.allclose(f.v, 0.0)
    _update(f, [0.02, 0.0, 0.0], 1 / 30)              # 2 cm in 1/30 s: 0.6 m/s if raw
    assert 0 < f.v[0, 0, 0] < 0.9 * 0.6                # shrunk towards the zero start
    assert f.p_vv[0, 0] < 1.0                          # and known better than before


def test_kalman_reduces_noise_on_a_still_joint():
    rng = np.random.default_rng(0)
    f = JointKalman(1, accel_noise=0.01, rows=1)
    out = [_update(f, rng.normal(0, 0.01, 3), i / 30.0).joints[0, 0] for i in range(300)]
    assert np.std(np.array(out)[50:]) < 0.5 * 0.01


def test_kalman_rejects_a_single_frame_outlier():
    f = JointKalman(1, rows=1)
    for i in range(10):
        _update(f, [0.0, 0.0, 1.0], i / 30)
    out = _update(f, [0.5, 0.0, 1.0], 10 / 30)        # one 0.5 m outlier
    assert not out.accepted[0, 0] and out.state[0, 0] == JointState.PREDICTED
    assert np.allclose(out.joints[0, 0], [0, 0, 1], atol=1e-6)   # not dragged towards it
    out = _update(f, [0.0, 0.0, 1.0], 11 / 30)
    assert out.accepted[0, 0] and abs(out.joints[0, 0, 0]) < 1e-3


def test_kalman_restarts_after_repeated_rejections():
    f = JointKalman(1, reinit_after=2, rows=1)
    for i in range(10):
        _update(f, [0.0, 0.0, 1.0], i / 30)
    assert not _update(f, [1.0, 0.0, 1.0], 10 / 30).accepted[0, 0]
    out = _update(f, [1.0, 0.0, 1.0], 11 / 30)        # second time: the joint really moved
    assert out.accepted[0, 0] and out.joints[0, 0, 0] == 1.0 and np.allclose(f.v, 0.0)


def test_kalman_holds_joints_in_gaps_with_growing_variance_then_forgets():
    f = JointKalman(1, max_gap_s=0.1, rows=1)
    for i in range(10):
        _update(f, [0.1 * i, 0.0, 0.0], i * 0.05)     # 2 m/s
    last = f.x[0, 0, 0]
    var = []
    for stamp in (0.5, 0.55):
        out = _update(f, [np.nan] * 3, stamp)
        assert out.state[0, 0] == JointState.PREDICTED
        assert out.joints[0, 0, 0] == last            # held, not extrapolated
        var.append(out.variance[0, 0])
    assert var[1] > var[0] > f.p_xx[0, 0]
    out = _update(f, [np.nan] * 3, 0.6)                # 0.15 s since the last update
    assert out.state[0, 0] == JointState.MISSING and np.isnan(out.joints).all()
    assert np.isnan(out.variance).all()
    out = _update(f, [3.0, 0.0, 0.0], 0.65)            # restarts from the observation
    assert out.state[0, 0] == JointState.TRIANGULATED and out.joints[0, 0, 0] == 3.0


def test_kalman_rows_follow_reindex():
    f = JointKalman(1)
    f.reindex(np.array([-1, -1]))
    f.update(np.array([[[1.0, 0, 0]], [[5.0, 0, 0]]]), np.full((2, 1), R), 0.0)
    f.reindex(np.array([1, -1]))                        # row 0 continues old row 1
    out = f.update(np.array([[[5.0, 0, 0]], [[9.0, 0, 0]]]), np.full((2, 1), R), 0.1)
    assert f.count[:, 0].tolist() == [2, 1]
    assert out.joints[:, 0, 0].tolist() == [5.0, 9.0]


def _live(tid, z, stamp, r=R, state=TrackState.CONFIRMED):
    """Return a published track whose filter accepted ``z [J, 3]`` (NaN: none)."""
    z = np.asarray(z, dtype=float)
    n = len(z)
    ok = np.isfinite(z[:, 0])
    js = np.where(ok, JointState.TRIANGULATED, JointState.MISSING).astype(np.uint8)
    return Track(track_id=tid, state=state, joints=z.copy(), confidence=np.where(ok, 0.8, 0),
                 joint_state=js, num_views=np.full(n, 2, np.uint8),
                 reprojection_error=np.zeros(n), position=np.full(3, np.nan),
                 velocity=np.full(3, np.nan), first_seen=0.0, last_observed=stamp,
                 joint_variance=np.where(ok, r, np.nan), measurement=z.copy(),
                 measurement_variance=np.where(ok, r, np.nan))


def test_fixed_lag_emits_each_set_lag_sets_later_with_its_own_key_and_stamp():
    sm = FixedLagSmoother(lag=3)
    out = []
    for k in range(10):
        done = sm.push(k, k / 25, [_live(1, [[0.1 * k, 0, 1]], k / 25)])
        assert (done is None) == (k < 3)
        if done is not None:
            out.append(done)
    assert [d[0] for d in out] == list(range(7))
    tail = sm.flush()
    assert [d[0] for d in tail] == [7, 8, 9] and sm.flush() == []
    for key, stamp, tracks in out + tail:
        assert stamp == key / 25 and [t.track_id for t in tracks] == [1]
        assert tracks[0].joints[0] == pytest.approx([0.1 * key, 0, 1])   # a line stays one


def test_fixed_lag_zero_passes_sets_through():
    sm = FixedLagSmoother(lag=0)
    tracks = [_live(1, [[0, 0, 1]], 0.0)]
    key, stamp, out = sm.push('a', 0.0, tracks)
    assert key == 'a' and out[0] is tracks[0]


def test_fixed_lag_reduces_noise_below_the_causal_filter():
    rng = np.random.default_rng(3)
    truth = np.array([[0.8 * k / 25, 0.0, 1.0] for k in range(200)])
    z = truth + rng.normal(0, 0.02, truth.shape)
    kf = JointKalman(1, rows=1)
    sm = FixedLagSmoother(lag=3)
    causal, smooth = {}, {}
    for k in range(200):
        out = _update(kf, z[k], k / 25, 0.02 ** 2)
        causal[k] = out.joints[0, 0]
        tr = _live(1, [z[k]], k / 25, 0.02 ** 2)
        done = sm.push(k, k / 25, [dataclasses.replace(tr, joints=out.joints[0])])
        if done is not None:
            smooth[done[0]] = done[2][0].joints[0]
    keys = range(20, 190)
    err_c = np.mean([np.linalg.norm(causal[k] - truth[k]) for k in keys])
    err_s = np.mean([np.linalg.norm(smooth[k] - truth[k]) for k in keys])
    err_z = np.mean([np.linalg.norm(z[k] - truth[k]) for k in keys])
    assert err_s < 0.8 * err_c < err_z


def test_fixed_lag_interpolates_a_gap_seen_on_both_sides():
    sm = FixedLagSmoother(lag=2)
    got = {}
    for k in range(8):
        z = [[0.1 * k, 0, 1], [np.nan] * 3 if k == 4 else [0.1 * k, 0.2, 1]]
        tr = _live(5, z, k / 25)
        if k == 4:                                   # the live output held joint 1
            tr.joints[1] = [0.3, 0.2, 1]
            tr.joint_state[1] = JointState.PREDICTED
        done = sm.push(k, k / 25, [tr])
        if done:
            got[done[0]] = done[2][0]
    assert got[4].joint_state.tolist() == [JointState.TRIANGULATED, JointState.PREDICTED]
    assert got[4].joints[1] == pytest.approx([0.4, 0.2, 1.0])
    deleted = _live(5, [[0, 0, 1], [0, 0, 1]], 0.0, state=TrackState.DELETED)
    assert sm.push(8, 8 / 25, [deleted]) is not None and sm.flush()[-1][2][0] is deleted


def test_interpolate_gaps():
    traj = np.arange(10, dtype=float)[:, None, None] * np.ones((1, 2, 3))
    traj[2:4, 0] = np.nan                      # gap of 2 inside: filled
    traj[5:9, 1] = np.nan                      # gap of 4: too long for max_gap 3
    traj[0, 1] = np.nan                        # leading gap: never filled
    out, filled = interpolate_gaps(traj, max_gap=3)
    assert np.allclose(out[2:4, 0], [[2.0] * 3, [3.0] * 3])
    assert filled[2:4, 0].all() and filled.sum() == 2
    assert np.isnan(out[5:9, 1]).all() and np.isnan(out[0, 1]).all()


def test_gaussian_smoothing_never_pulls_towards_zero():
    # the reference implementation let missing samples (zeros) bleed into the signal
    traj = np.full((50, 1, 3), 2.0)
    traj[20:22] = np.nan
    traj[30:45] = np.nan
    out, filled = gaussian_smooth(traj, sigma_frames=2.0, max_gap_frames=5)
    ok = np.isfinite(out[:, 0, 0])
    assert np.allclose(out[ok], 2.0)                          # constant stays constant
    assert ok[20] and ok[21] and filled[20:22, 0].all()       # short gap filled
    assert not ok[30:45].any()                                # long gap stays missing
    assert ok[0] and ok[-1]                                   # ends are not attenuated


def test_gaussian_smoothing_reduces_noise_and_keeps_a_ramp():
    rng = np.random.default_rng(1)
    t = np.arange(200, dtype=float)
    ramp = np.stack([0.01 * t, 0 * t, 0 * t], 1)[:, None]
    out, _ = gaussian_smooth(ramp + rng.normal(0, 0.01, ramp.shape), sigma_frames=3.0)
    err = out[10:-10] - ramp[10:-10]
    assert np.std(err) < 0.5 * 0.01 and abs(err.mean()) < 0.002


def _track(tid, joints, state=JointState.TRIANGULATED):
    n = len(joints)
    js = np.where(np.isfinite(joints[:, 0]), state, JointState.MISSING).astype(np.uint8)
    return Track(track_id=tid, state=TrackState.CONFIRMED, joints=joints,
                 confidence=np.where(js > 0, 0.8, 0.0), joint_state=js,
                 num_views=np.full(n, 2, np.uint8), reprojection_error=np.zeros(n),
                 position=np.full(3, np.nan), velocity=np.full(3, np.nan), first_seen=0.0,
                 last_observed=0.0)


def test_smooth_track_sequence_fills_and_marks_predicted():
    frames = []
    for i in range(20):
        joints = np.array([[0.1 * i, 0.0, 1.0], [0.1 * i, 0.2, 1.0]])
        if i in (8, 9):
            joints[1] = np.nan
        tracks = [_track(1, joints)]
        if i == 19:
            tracks.append(Track(**{**tracks[0].__dict__, 'track_id': 7,
                                   'state': TrackState.DELETED}))
        frames.append(tracks)
    out = smooth_track_sequence(frames, sigma_frames=1.0, max_gap_frames=3,
                                root_joints=(0, 1))
    assert out[8][0].joint_state.tolist() == [JointState.TRIANGULATED, JointState.PREDICTED]
    assert out[8][0].joints[1] == pytest.approx([0.8, 0.2, 1.0])
    assert out[8][0].confidence[1] == pytest.approx(0.8)
    assert out[10][0].position == pytest.approx([1.0, 0.1, 1.0])
    assert out[19][1] is frames[19][1]                         # tombstones pass through
    assert frames[8][0].joint_state[1] == JointState.MISSING   # input untouched
