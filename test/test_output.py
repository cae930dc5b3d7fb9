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

"""Live publication rules, public ids and the fixed-lag stream (core.output)."""

from mv3dpose_ros.core.fusion.pipeline import Fusion
from mv3dpose_ros.core.live.output import LiveOutput, TrackPublisher
from mv3dpose_ros.core.types import JointState, Track, TrackState
from mv3dpose_ros.sim import make_scene
import numpy as np

J = 4


def _t(tid, state, last_observed, x=0.0, measured=True):
    """Return a ``Fusion.step``-like track (internal id ``tid``) standing at ``x``."""
    joints = np.array([[x, 0.0, 0.2 * j] for j in range(J)])
    z = joints if measured else np.full((J, 3), np.nan)
    js = np.full(J, JointState.TRIANGULATED if measured else JointState.PREDICTED, np.uint8)
    return Track(track_id=tid, state=state, joints=joints, confidence=np.full(J, 0.9),
                 joint_state=js, num_views=np.full(J, 3, np.uint8),
                 reprojection_error=np.zeros(J), position=joints[:2].mean(0),
                 velocity=np.zeros(3), first_seen=0.0, last_observed=last_observed,
                 joint_variance=np.full(J, 1e-4), position_covariance=np.eye(3) * 5e-5,
                 measurement=z, measurement_variance=np.full(J, 1e-4 if measured else np.nan))


C, T, K, D = (TrackState.CONFIRMED, TrackState.TENTATIVE, TrackState.COASTING,
              TrackState.DELETED)


def _ids(tracks):
    return [(t.track_id, t.state.name) for t in tracks]


def test_public_ids_are_given_at_first_publication_without_gaps_and_never_reused():
    pub = TrackPublisher(publish_coast_s=0.15)
    # internal 5 and 6 are tentative (not published), 7 is confirmed at once
    assert _ids(pub.publish([_t(5, T, 0.0), _t(6, T, 0.0), _t(7, C, 0.0)], 0.0)) == \
        [(1, 'CONFIRMED')]
    # 5 dies tentative: no id used, no tombstone; 6 is confirmed: the next id, 2
    out = pub.publish([_t(5, D, 0.0), _t(6, C, 0.04), _t(7, C, 0.04)], 0.04)
    assert _ids(out) == [(1, 'CONFIRMED'), (2, 'CONFIRMED')]
    out = pub.publish([_t(6, D, 0.04), _t(7, C, 0.08), _t(8, C, 0.08)], 0.08)
    assert _ids(out) == [(1, 'CONFIRMED'), (3, 'CONFIRMED'), (2, 'DELETED')]
    assert pub.published_ids == [1, 3]
    tombs = pub.reset([_t(7, D, 0.08), _t(8, D, 0.08), _t(9, D, 0.08)])
    assert _ids(tombs) == [(1, 'DELETED'), (3, 'DELETED')]
    assert _ids(pub.publish([_t(10, C, 0.12)], 0.12)) == [(4, 'CONFIRMED')]   # not reused


def test_coasting_is_published_for_publish_coast_s_then_withheld_until_seen_or_deleted():
    pub = TrackPublisher(publish_coast_s=0.15)
    pub.publish([_t(1, C, 0.0)], 0.0)
    shown = [bool(pub.publish([_t(1, K, 0.0)], s)) for s in (0.04, 0.08, 0.12, 0.16, 0.2)]
    assert shown == [True, True, True, False, False]
    assert _ids(pub.publish([_t(1, C, 0.24)], 0.24)) == [(1, 'CONFIRMED')]   # recovered
    pub.publish([_t(1, K, 0.24)], 0.6)
    assert _ids(pub.publish([_t(1, D, 0.24)], 1.3)) == [(1, 'DELETED')]      # tombstone
    tentative = TrackPublisher(publish_tentative=True)
    assert _ids(tentative.publish([_t(4, T, 0.0)], 0.0)) == [(1, 'TENTATIVE')]


def test_fixed_lag_settles_gaps_and_late_confirmations_within_the_lag():
    out = LiveOutput(publish_coast_s=0.05, lag=3, root_joints=(0, 1))
    stream = [
        [_t(1, C, 0.0, 0.0), _t(2, T, 0.0, 3.0)],
        [_t(1, K, 0.0, 0.0, measured=False), _t(2, T, 0.04, 3.0)],
        [_t(1, K, 0.0, 0.0, measured=False), _t(2, C, 0.08, 3.0)],     # 2 confirmed now
        [_t(1, C, 0.12, 0.12), _t(2, C, 0.12, 3.0)],                    # 1 seen again
        [_t(1, C, 0.16, 0.16), _t(2, C, 0.16, 3.0)],
    ]
    live, lagged = [], []
    for k, tracks in enumerate(stream):
        published, done = out.step(tracks, 0.04 * k, k)
        live.append(_ids(published))
        if done is not None:
            lagged.append(done)
    lagged += out.flush()
    assert live[1] == [(1, 'COASTING')] and live[2] == [(2, 'CONFIRMED')]   # 1 withheld
    assert [d[0] for d in lagged] == [0, 1, 2, 3, 4]
    assert _ids(lagged[0][2]) == [(1, 'CONFIRMED'), (2, 'CONFIRMED')]      # 2 from frame 0
    assert _ids(lagged[2][2]) == [(1, 'COASTING'), (2, 'CONFIRMED')]       # gap bridged
    bridged = lagged[2][2][0]
    assert bridged.joint_state.tolist() == [JointState.PREDICTED] * J      # interpolated
    assert 0.0 < bridged.joints[0, 0] < 0.12


def test_live_output_of_a_synthetic_scene_has_dense_ids_and_exact_stamps():
    scene = make_scene(num_cameras=4, num_people=3, num_frames=60, seed=2)
    fusion = Fusion(scene.cameras, scene.layout)
    out = LiveOutput(fusion.config.publish_coast_s, lag=3, root_joints=(11, 12))
    seen, lagged = set(), 0
    for k, (views, stamp) in enumerate(zip(scene.views, scene.stamps)):
        stamp_ns = 1_700_000_000_000_000_001 + k * 40_000_000
        published, done = out.step(fusion.step(views, stamp, stamp_ns), stamp, stamp_ns)
        for t in published:
            seen.add(t.track_id)
            if t.state == TrackState.CONFIRMED:
                assert t.last_observed_ns == stamp_ns
                assert np.isfinite(t.joint_variance[t.valid]).all()
                assert t.position_covariance[0, 0] > 0
        if done is not None:
            lagged += 1
            assert done[0] == stamp_ns - 3 * 40_000_000            # its own stamp, 3 sets back
    assert sorted(seen) == list(range(1, len(seen) + 1)) and len(seen) == 3
    assert lagged == 57


def test_fixed_lag_skipped_while_unwanted_then_exactly_as_if_never_skipped():
    """fusion_node skips the fixed-lag estimate while nobody subscribes; a joiner sees no gap."""
    scene = make_scene(num_cameras=4, num_people=3, num_frames=60, seed=4)
    fusion = Fusion(scene.cameras, scene.layout)
    steps = [fusion.step(views, stamp) for views, stamp in zip(scene.views, scene.stamps)]
    always = LiveOutput(fusion.config.publish_coast_s, lag=3, root_joints=(11, 12))
    lazy = LiveOutput(fusion.config.publish_coast_s, lag=3, root_joints=(11, 12))
    compared = 0
    for k, (tracks, stamp) in enumerate(zip(steps, scene.stamps)):
        want = not 10 <= k < 40           # unsubscribed for 30 sets, then subscribed again
        pub_a, done_a = always.step(tracks, stamp, k)
        pub_l, done_l = lazy.step(tracks, stamp, k, smoothed=want)
        assert _ids(pub_a) == _ids(pub_l)
        if not want or done_a is None:
            assert done_l is None
            continue
        assert done_l[0] == done_a[0] and _ids(done_l[2]) == _ids(done_a[2])
        for a, b in zip(done_a[2], done_l[2]):
            assert a.state == b.state
            np.testing.assert_array_equal(a.joints, b.joints)
            np.testing.assert_array_equal(a.joint_variance, b.joint_variance)
        compared += k >= 40
    assert compared == 20
    assert _ids(always.flush()[-1][2]) == _ids(lazy.flush()[-1][2])
