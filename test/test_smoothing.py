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

"""Causal alpha-beta filter and offline Gaussian smoothing with gap interpolation."""

from mv3dpose_ros.core.smoothing import (CausalFilter, gaussian_smooth, interpolate_gaps,
                                         smooth_track_sequence)
from mv3dpose_ros.core.types import JointState, Track, TrackState
import numpy as np
import pytest


def test_causal_filter_has_no_lag_on_constant_velocity():
    f = CausalFilter(2, alpha=0.5, beta=0.2)
    for i in range(60):
        t = i / 30.0
        z = np.array([[1.2 * t, 0.0, 1.0], [0.0, -0.5 * t, 0.3]])
        x, state = f.update(z, t)
    assert np.allclose(x, z, atol=1e-9)                  # exact after convergence
    assert (state == JointState.TRIANGULATED).all()
    assert np.allclose(f.v[0], [[1.2, 0, 0], [0, -0.5, 0]], atol=1e-6)


def test_causal_filter_reduces_noise_on_a_still_joint():
    rng = np.random.default_rng(0)
    f = CausalFilter(1, alpha=0.4, beta=0.1)
    out = []
    for i in range(400):
        x, _ = f.update(rng.normal(0, 0.01, (1, 3)), i / 30.0)
        out.append(x[0])
    assert np.std(np.array(out)[100:]) < 0.75 * 0.01


def test_causal_filter_fills_short_gaps_then_forgets():
    f = CausalFilter(1, max_gap_s=0.1)
    for i in range(10):
        f.update(np.array([[0.1 * i, 0.0, 0.0]]), i * 0.05)   # 2 m/s
    x, state = f.update(np.full((1, 3), np.nan), 0.5)
    assert state[0] == JointState.PREDICTED and x[0, 0] == pytest.approx(1.0, abs=1e-6)
    x, state = f.update(np.full((1, 3), np.nan), 0.55)
    assert state[0] == JointState.PREDICTED
    x, state = f.update(np.full((1, 3), np.nan), 0.6)         # 0.15 s since last seen
    assert state[0] == JointState.MISSING and np.isnan(x).all()
    x, state = f.update(np.array([[3.0, 0.0, 0.0]]), 0.65)   # restarts from the observation
    assert state[0] == JointState.TRIANGULATED and x[0, 0] == 3.0


def test_causal_filter_restarts_on_a_jump():
    f = CausalFilter(1, reset_m=0.5)
    for i in range(5):
        f.update(np.zeros((1, 3)), i * 0.1)
    x, _ = f.update(np.array([[2.0, 0.0, 0.0]]), 0.5)
    assert x[0, 0] == 2.0 and np.allclose(f.v, 0.0)


def test_causal_filter_rows_follow_reindex():
    f = CausalFilter(1, rows=0)
    f.reindex(np.array([-1, -1]))
    f.update(np.array([[[1.0, 0, 0]], [[5.0, 0, 0]]]), 0.0)
    f.reindex(np.array([1, -1]))                              # row 0 continues old row 1
    x, state = f.update(np.array([[[5.0, 0, 0]], [[9.0, 0, 0]]]), 0.1)
    assert f.count[:, 0].tolist() == [2, 1]
    assert x[:, 0, 0].tolist() == [5.0, 9.0]


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
