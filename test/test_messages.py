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

"""Unit tests of the numpy / Track <-> message conversions (no DDS)."""

from mv3dpose_msgs.msg import Joint3D, Keypoint2D, Person2D, Person2DArray, TrackedSkeleton
from mv3dpose_ros.core.types import JointState, Track, TrackState
from mv3dpose_ros.ros.messages import (InvalidMessage, message_to_dict, msg_to_tracks, ns_to_stamp,
                                       numpy_to_person2d_array, person2d_array_to_numpy,
                                       stamp_to_ns, tracks_to_msg)
import numpy as np
import pytest
from std_msgs.msg import Header


def _track(track_id=7, joints=4):
    xyz = np.arange(joints * 3, dtype=float).reshape(joints, 3)
    xyz[1] = np.nan
    states = np.full(joints, JointState.TRIANGULATED, np.uint8)
    states[1] = JointState.MISSING
    states[2] = JointState.PREDICTED
    err = np.full(joints, 1.5)
    err[2] = np.nan
    return Track(track_id=track_id, state=TrackState.CONFIRMED, joints=xyz,
                 confidence=np.linspace(0.1, 0.9, joints), joint_state=states,
                 num_views=np.full(joints, 3, np.uint8), reprojection_error=err,
                 position=np.array([1.0, 2.0, 0.9]), velocity=np.full(3, np.nan),
                 first_seen=10.5, last_observed=12.25, age=5, missed=1, score=0.8,
                 source_cameras=('cam0', 'cam2'))


def _all_floats(value):
    if isinstance(value, dict):
        for v in value.values():
            yield from _all_floats(v)
    elif isinstance(value, list):
        for v in value:
            yield from _all_floats(v)
    elif isinstance(value, float):
        yield value


def test_tracks_to_msg_has_no_nan_and_explicit_validity():
    msg = tracks_to_msg([_track()], Header(frame_id='map'), 'coco17')
    assert all(np.isfinite(v) for v in _all_floats(message_to_dict(msg)))
    skel = msg.skeletons[0]
    assert skel.state == TrackedSkeleton.CONFIRMED
    assert skel.joints[1].state == Joint3D.MISSING
    assert (skel.joints[1].position.x, skel.joints[1].confidence) == (0.0, 0.0)
    assert skel.joints[2].state == Joint3D.PREDICTED
    assert skel.joints[2].reprojection_error == -1.0
    assert not skel.velocity_valid
    assert skel.position_covariance[0] == -1.0
    assert list(skel.source_cameras) == ['cam0', 'cam2']


def test_track_round_trip_through_message():
    original = _track()
    back = msg_to_tracks(tracks_to_msg([original], Header(), 'coco17'))[0]
    assert back.track_id == original.track_id and back.state == original.state
    np.testing.assert_array_equal(back.joint_state, original.joint_state)
    np.testing.assert_allclose(back.joints, original.joints, equal_nan=True)
    expected_conf = np.where(original.valid, original.confidence, 0.0)
    np.testing.assert_allclose(back.confidence, expected_conf, rtol=1e-6)
    assert back.first_seen == pytest.approx(10.5) and back.last_observed == pytest.approx(12.25)
    assert np.all(np.isnan(back.velocity))


def test_uncertainty_and_exact_stamps_reach_the_message_and_come_back():
    track = _track()
    track.joint_variance = np.array([1e-4, np.nan, 4e-4, 9e-4])
    track.position_covariance = np.eye(3) * 2.5e-4
    track.first_seen_ns = 1_700_000_000_123_456_789
    track.last_observed_ns = 1_700_000_001_987_654_321
    msg = tracks_to_msg([track], Header(frame_id='map'), 'coco17')
    skel = msg.skeletons[0]
    assert list(skel.position_covariance) == pytest.approx((np.eye(3) * 2.5e-4).ravel().tolist())
    assert [j.position_variance for j in skel.joints] == pytest.approx([1e-4, -1, 4e-4, 9e-4])
    assert stamp_to_ns(skel.first_seen) == 1_700_000_000_123_456_789
    assert stamp_to_ns(skel.last_observed) == 1_700_000_001_987_654_321
    back = msg_to_tracks(msg)[0]
    np.testing.assert_allclose(back.joint_variance, [1e-4, np.nan, 4e-4, 9e-4], rtol=1e-6)
    np.testing.assert_allclose(back.position_covariance, np.eye(3) * 2.5e-4)
    assert back.last_observed_ns == 1_700_000_001_987_654_321
    track.position_covariance = np.full((3, 3), np.nan)        # unknown: [0] = -1, no NaN
    skel = tracks_to_msg([track], Header(), 'coco17').skeletons[0]
    assert skel.position_covariance[0] == -1.0 and np.isfinite(skel.position_covariance).all()


def test_person2d_round_trip_and_missing_joints():
    rng = np.random.default_rng(0)
    poses = np.concatenate([rng.uniform(0, 500, (3, 17, 2)), rng.uniform(0.1, 1, (3, 17, 1))],
                           axis=-1)
    poses[0, 5] = np.nan
    poses[1, 6, 2] = 0.0
    msg = numpy_to_person2d_array(poses, Header(), 'cam1', 640, 480, 'coco17')
    back = person2d_array_to_numpy(msg, 17)
    assert back.shape == (3, 17, 3)
    assert back[0, 5, 2] == 0.0 and back[1, 6, 2] == 0.0
    keep = poses[..., 2] > 0
    keep[0, 5] = False
    np.testing.assert_allclose(back[keep], poses[keep], rtol=1e-5)
    roi = msg.persons[2].roi
    assert 0 <= roi.x_offset and roi.x_offset + roi.width <= 640


def _bad_message(kind):
    msg = Person2DArray(camera_id='cam0', layout='coco17')
    kps = [Keypoint2D(x=1.0, y=2.0, confidence=0.5) for _ in range(17)]
    if kind == 'count':
        kps = kps[:12]
    elif kind == 'nan':
        kps[3] = Keypoint2D(x=float('nan'), y=1.0, confidence=0.5)
    elif kind == 'negative':
        kps[4] = Keypoint2D(x=1.0, y=1.0, confidence=-0.1)
    msg.persons = [Person2D(keypoints=kps)]
    return msg


@pytest.mark.parametrize('kind,reason', [('count', 'keypoints per person'), ('nan', 'NaN'),
                                         ('negative', 'confidence outside')])
def test_bad_person2d_is_rejected_with_reason(kind, reason):
    with pytest.raises(InvalidMessage, match=reason):
        person2d_array_to_numpy(_bad_message(kind), 17)


def test_stamp_conversion_is_exact():
    ns = 1_700_000_123_456_789_012
    assert stamp_to_ns(ns_to_stamp(ns)) == ns
