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

"""Tracker: gated matching, life cycle, ids, filtered motion, ground-plane fallback."""

from mv3dpose_ros.core.tracking.tracker import pose_distance, Tracker, TrackerConfig
from mv3dpose_ros.core.types import TrackState
import numpy as np
import pytest

J = 10


def _pose(x, y, rng=None):
    """Return a person-shaped blob of J joints standing at (x, y)."""
    base = np.stack([np.zeros(J), np.zeros(J), np.linspace(0.1, 1.7, J)], axis=1)
    base[:, 0] += np.linspace(-0.2, 0.2, J)
    return base + np.array([x, y, 0.0])


def _states(tracker):
    tracks = tracker.tracks
    return {int(i): TrackState(int(s)).name for i, s in zip(tracks.ids, tracks.state)}


def test_pose_distance_mean_and_ground_fallback():
    a = _pose(0, 0)[None]
    b = _pose(0.3, 0.4)[None]
    assert pose_distance(a, b)[0, 0] == pytest.approx(0.5)
    upper, lower = a.copy(), b.copy()
    upper[0, :5] = np.nan
    lower[0, 5:] = np.nan                            # no joint in common
    d = pose_distance(upper, lower, min_shared_joints=3)[0, 0]
    cu = np.nanmean(upper[0], axis=0)
    cl = np.nanmean(lower[0], axis=0)
    assert d == pytest.approx(np.linalg.norm((cu - cl)[:2]))
    empty = np.full_like(a, np.nan)
    assert pose_distance(empty, b)[0, 0] == np.inf


def test_life_cycle_and_ids():
    cfg = TrackerConfig(confirm_hits=3, max_coast_s=0.5, predict=False)
    tr = Tracker(J, cfg)
    p = _pose(0, 0)[None]
    upd = tr.update(p, 0.0)
    assert upd.detection.tolist() == [0] and upd.previous.tolist() == [-1]
    assert _states(tr) == {1: 'TENTATIVE'}
    tr.update(p, 0.1)
    assert _states(tr) == {1: 'TENTATIVE'}
    tr.update(p, 0.2)
    assert _states(tr) == {1: 'CONFIRMED'}
    upd = tr.update(p[:0], 0.3)                      # missed: coast
    assert _states(tr) == {1: 'COASTING'} and upd.detection.tolist() == [-1]
    assert int(tr.tracks.missed[0]) == 1
    tr.update(p, 0.4)                                # seen again: confirmed, same id
    assert _states(tr) == {1: 'CONFIRMED'} and int(tr.tracks.missed[0]) == 0
    tr.update(p[:0], 0.5)
    tr.update(p[:0], 0.9)
    assert _states(tr) == {1: 'COASTING'}
    upd = tr.update(p[:0], 0.95)                     # 0.55 s unobserved > max_coast_s
    assert _states(tr) == {} and upd.deleted.ids.tolist() == [1]
    assert upd.deleted.state.tolist() == [TrackState.DELETED]
    tr.update(p, 1.0)                                # a new person: id 2, never 1 again
    assert _states(tr) == {2: 'TENTATIVE'}


def test_tentative_track_dies_on_first_miss_and_reset_keeps_counting():
    tr = Tracker(J, TrackerConfig(confirm_hits=3))
    tr.update(_pose(0, 0)[None], 0.0)
    upd = tr.update(np.zeros((0, J, 3)), 0.1)
    assert upd.deleted.ids.tolist() == [1] and len(tr.tracks) == 0
    tr.update(np.stack([_pose(0, 0), _pose(2, 0)]), 0.2)
    dropped = tr.reset()
    assert dropped.ids.tolist() == [2, 3]
    assert (dropped.state == TrackState.DELETED).all()
    tr.update(_pose(0, 0)[None], 0.3)
    assert tr.tracks.ids.tolist() == [4]


def test_gate_starts_a_new_track_for_a_far_pose():
    tr = Tracker(J, TrackerConfig(confirm_hits=1, predict=False, gate_growth_mps=0.0,
                                  recovery_gate_m=0.0))
    tr.update(_pose(0, 0)[None], 0.0)
    tr.update(_pose(0.15, 0)[None], 0.1)             # 0.15 m < 0.2 m: same track
    assert tr.tracks.ids.tolist() == [1]
    upd = tr.update(_pose(0.5, 0)[None], 0.2)        # 0.35 m: new track, old one coasts
    assert tr.tracks.ids.tolist() == [1, 2]
    assert upd.detection.tolist() == [-1, 0]


def test_recovery_gate_keeps_the_track_through_one_noisy_pose():
    tr = Tracker(J, TrackerConfig(confirm_hits=1, predict=False, gate_growth_mps=0.0,
                                  recovery_gate_m=0.5))
    tr.update(_pose(0, 0)[None], 0.0)
    tr.update(_pose(0.35, 0)[None], 0.1)
    assert tr.tracks.ids.tolist() == [1]


def test_two_people_crossing_keep_their_ids():
    tr = Tracker(J, TrackerConfig(confirm_hits=1))
    ids = []
    for i in range(40):
        t = i / 10.0
        a, b = _pose(-2 + 0.1 * i, 0.4), _pose(2 - 0.1 * i, -0.4)
        order = [b, a] if i % 2 else [a, b]          # detection order must not matter
        upd = tr.update(np.stack(order), t)
        who = {int(tr.tracks.ids[k]): d for k, d in enumerate(upd.detection)}
        ids.append(who[1] == (1 if i % 2 else 0))
    assert tr.tracks.ids.tolist() == [1, 2] and all(ids)


@pytest.mark.parametrize('predict', [True, False])
def test_constant_velocity_prediction_bridges_dropped_frames(predict):
    cfg = TrackerConfig(confirm_hits=1, predict=predict, gate_growth_mps=0.0,
                        recovery_gate_m=0.0)
    tr = Tracker(J, cfg)
    for i in range(10):                              # walking at 1.5 m/s
        tr.update(_pose(0.15 * i, 0)[None], 0.1 * i)
    assert tr.tracks.velocity[0] == pytest.approx([1.5, 0, 0], abs=0.05)
    tr.update(_pose(2.1, 0)[None], 1.4)              # four frames lost: 0.75 m further
    assert tr.tracks.ids.tolist() == ([1] if predict else [1, 2])


def test_body_velocity_comes_from_the_filtered_state():
    # One pose that mixes two people jumps 0.45 m: it may keep the track (recovery gate),
    # but neither the track's pose nor its velocity may follow it.
    tr = Tracker(J, TrackerConfig(confirm_hits=1, recovery_gate_m=0.5))
    for i in range(10):
        tr.update(_pose(0, 0)[None], i / 25)
    upd = tr.update(_pose(0.45, 0)[None], 10 / 25)
    assert tr.tracks.ids.tolist() == [1] and upd.detection.tolist() == [0]
    assert not upd.filtered.accepted.any()           # every joint failed its innovation gate
    assert np.abs(tr.tracks.velocity[0]).max() < 0.05
    assert np.abs(tr.tracks.pose[0, :, 0] - _pose(0, 0)[:, 0]).max() < 0.01
    upd = tr.update(_pose(0, 0)[None], 11 / 25)      # the person is where they were
    assert upd.detection.tolist() == [0] and upd.filtered.accepted.all()


def test_tracks_are_deleted_after_max_coast_s_whatever_the_gate_does():
    # The gate widens with the time a track is unseen; before, a track unseen for 5 s (or an
    # hour) still matched a pose there and its id went on.
    for gap in (1.5, 5.0, 3600.0):
        tr = Tracker(J, TrackerConfig(confirm_hits=1, max_coast_s=1.0, gate_growth_mps=1.0))
        tr.update(_pose(0, 0)[None], 0.0)
        upd = tr.update(_pose(0.1, 0)[None], gap)
        assert upd.deleted.ids.tolist() == [1], gap
        assert tr.tracks.ids.tolist() == [2] and upd.previous.tolist() == [-1]


def test_well_supported_births_are_confirmed_at_once():
    tr = Tracker(J, TrackerConfig(confirm_hits=3))
    upd = tr.update(np.stack([_pose(0, 0), _pose(2, 0)]), 0.0,
                    confirm_at_birth=lambda rows: rows == 1)
    assert _states(tr) == {1: 'TENTATIVE', 2: 'CONFIRMED'}
    assert upd.filtered.state.shape == (2, J)


def test_stamps_are_kept_in_integer_nanoseconds():
    tr = Tracker(J)
    stamp_ns = 1_700_000_000_123_456_789             # not representable as float seconds
    tr.update(_pose(0, 0)[None], stamp_ns / 1e9, stamp_ns=stamp_ns)
    assert tr.tracks.first_seen_ns.tolist() == [stamp_ns]
    tr.update(_pose(0, 0)[None], (stamp_ns + 40_000_001) / 1e9, stamp_ns=stamp_ns + 40_000_001)
    assert tr.tracks.last_observed_ns.tolist() == [stamp_ns + 40_000_001]


def test_birth_rules():
    tr = Tracker(J, TrackerConfig(min_birth_joints=6))
    sparse = _pose(0, 0)
    sparse[:5] = np.nan                              # five joints: too thin to start a track
    tr.update(np.stack([sparse, _pose(2, 0), _pose(4, 0)]), 0.0,
              can_birth=np.array([True, False, True]))
    assert len(tr.tracks) == 1 and tr.tracks.pose[0, 0, 0] == pytest.approx(4 - 0.2)


def test_all_missing_pose_does_not_crash_or_match():
    tr = Tracker(J)
    tr.update(_pose(0, 0)[None], 0.0)
    upd = tr.update(np.full((1, J, 3), np.nan), 0.1)
    assert upd.deleted.ids.tolist() == [1] and len(tr.tracks) == 0
