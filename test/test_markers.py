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

"""Unit tests of the RViz markers: never NaN, only valid bones, stable colours, DELETEALL."""

import math

from mv3dpose_ros.core.skeleton import get_layout
from mv3dpose_ros.core.types import JointState, Track, TrackState
from mv3dpose_ros.ros.markers import MarkerOptions, tracks_to_markers, tracks_to_markers_cdr
from mv3dpose_ros.ros.messages import message_to_dict
from mv3dpose_ros.viz.palette import track_rgb
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Header
from visualization_msgs.msg import Marker, MarkerArray

LAYOUT = get_layout('coco17')
J = LAYOUT.num_joints


def make_track(track_id=1, state=TrackState.CONFIRMED, missing=(), predicted=(), nan_pos=False,
               rng=None):
    rng = rng or np.random.default_rng(track_id)
    joints = rng.uniform(-2, 2, size=(J, 3)) + [0, 0, 1]
    js = np.full(J, JointState.TRIANGULATED, dtype=np.uint8)
    js[list(predicted)] = JointState.PREDICTED
    js[list(missing)] = JointState.MISSING
    joints[list(missing)] = np.nan
    root = np.full(3, np.nan) if nan_pos else joints[list(LAYOUT.root_joints)].mean(axis=0)
    return Track(track_id=track_id, state=state, joints=joints, confidence=np.ones(J),
                 joint_state=js, num_views=np.full(J, 3, np.uint8),
                 reprojection_error=np.ones(J), position=root, velocity=np.array([0.1, 0, 0]),
                 first_seen=1.0, last_observed=2.0)


def all_floats(marker):
    vals = [marker.pose.position.x, marker.pose.position.y, marker.pose.position.z,
            marker.pose.orientation.x, marker.pose.orientation.y, marker.pose.orientation.z,
            marker.pose.orientation.w, marker.scale.x, marker.scale.y, marker.scale.z,
            marker.color.r, marker.color.g, marker.color.b, marker.color.a]
    vals += [v for p in marker.points for v in (p.x, p.y, p.z)]
    vals += [v for c in marker.colors for v in (c.r, c.g, c.b, c.a)]
    return vals


def by_ns(arr, suffix):
    return [m for m in arr.markers if m.ns.endswith(suffix) and m.action == Marker.ADD]


def header():
    h = Header(frame_id='map')
    h.stamp.sec = 12
    return h


def test_deleteall_first_per_namespace_then_adds():
    arr = tracks_to_markers([make_track(1), make_track(2)], LAYOUT.bones, header())
    deletes = [m for m in arr.markers if m.action == Marker.DELETEALL]
    assert arr.markers[:len(deletes)] == deletes
    assert {m.ns for m in deletes} == {'mv3dpose/bones', 'mv3dpose/joints', 'mv3dpose/labels',
                                       'mv3dpose/velocity'}
    assert all(m.ns for m in deletes)          # an empty ns would wipe every namespace
    assert len(by_ns(arr, 'bones')) == 2 and len(by_ns(arr, 'joints')) == 2
    labels = by_ns(arr, 'labels')
    assert [m.text for m in labels] == ['1 confirmed', '2 confirmed']
    assert all(m.header.frame_id == 'map' and m.header.stamp.sec == 12 for m in arr.markers)
    assert all(m.lifetime.nanosec == 500_000_000 for m in arr.markers if m.action == Marker.ADD)


def test_bones_only_between_valid_joints():
    missing = [LAYOUT.index('left_elbow'), LAYOUT.index('right_knee'), LAYOUT.index('nose')]
    track = make_track(3, missing=missing)
    (bones,) = by_ns(tracks_to_markers([track], LAYOUT.bones, header()), 'bones')
    assert bones.type == Marker.LINE_LIST and len(bones.points) % 2 == 0
    pts = np.array([[p.x, p.y, p.z] for p in bones.points]).reshape(-1, 2, 3)
    valid = [b for b in LAYOUT.bones if b[0] not in missing and b[1] not in missing]
    expected = track.joints[np.array(valid)]
    np.testing.assert_allclose(pts, expected)
    (joints,) = by_ns(tracks_to_markers([track], LAYOUT.bones, header()), 'joints')
    assert joints.type == Marker.SPHERE_LIST
    assert len(joints.points) == J - len(missing) == len(joints.colors)


@pytest.mark.parametrize('seed', range(20))
def test_never_nan_random_tracks(seed):
    rng = np.random.default_rng(seed)
    tracks = []
    for tid in range(1, 6):
        missing = rng.choice(J, size=rng.integers(0, J + 1), replace=False)
        predicted = [j for j in rng.choice(J, size=3, replace=False) if j not in missing]
        state = TrackState(int(rng.integers(0, 4)))
        t = make_track(int(rng.integers(1, 2**63)), state, missing, predicted,
                       nan_pos=bool(rng.random() < 0.3), rng=rng)
        t.velocity = np.array([np.nan, 0, 0]) if rng.random() < 0.5 else np.zeros(3)
        tracks.append(t)
    opts = MarkerOptions(show_velocity=True)
    arr = tracks_to_markers(tracks, LAYOUT.bones, header(), opts)
    for m in arr.markers:
        assert all(math.isfinite(v) for v in all_floats(m)), m
        assert 0 <= m.id < 2**31
        if m.type == Marker.LINE_LIST:
            assert len(m.points) > 0 and len(m.points) % 2 == 0
        if m.type == Marker.SPHERE_LIST:
            assert len(m.points) > 0 and len(m.colors) == len(m.points)


def test_all_joints_missing_track_gives_no_points_but_no_crash():
    track = make_track(4, missing=range(J), nan_pos=True)
    arr = tracks_to_markers([track], LAYOUT.bones, header())
    assert all(m.action == Marker.DELETEALL for m in arr.markers)


def test_deleted_tracks_not_drawn_and_coasting_dimmed():
    arr = tracks_to_markers([make_track(5, TrackState.DELETED),
                             make_track(6, TrackState.COASTING),
                             make_track(7, TrackState.CONFIRMED, predicted=[0, 1])],
                            LAYOUT.bones, header())
    assert {m.id for m in by_ns(arr, 'bones')} == {6, 7}
    colors = {m.id: m.color.a for m in by_ns(arr, 'joints')}
    assert colors[6] < colors[7] == 1.0
    (j7,) = [m for m in by_ns(arr, 'joints') if m.id == 7]
    assert j7.colors[0].a < 1.0 and j7.colors[2].a == 1.0


def test_colours_stable_and_distinct():
    assert track_rgb(42) == track_rgb(42)
    cols = np.array([track_rgb(i) for i in range(1, 9)])
    dist = np.linalg.norm(cols[:, None] - cols[None], axis=-1)
    assert dist[~np.eye(8, dtype=bool)].min() > 0.05
    a1 = tracks_to_markers([make_track(9)], LAYOUT.bones, header())
    a2 = tracks_to_markers([make_track(9, rng=np.random.default_rng(99))], LAYOUT.bones,
                           header())
    assert by_ns(a1, 'bones')[0].color == by_ns(a2, 'bones')[0].color


def test_big_track_id_maps_into_int32():
    arr = tracks_to_markers([make_track(2**40 + 3)], LAYOUT.bones, header())
    assert by_ns(arr, 'bones')[0].id == (2**40 + 3) % 2**31


@pytest.mark.parametrize('seed', range(10))
def test_cdr_markers_equal_serialised_marker_array(seed):
    rng = np.random.default_rng(100 + seed)
    tracks = []
    for _ in range(int(rng.integers(0, 7))):
        missing = rng.choice(J, size=rng.integers(0, J + 1), replace=False)
        predicted = [j for j in rng.choice(J, size=4, replace=False) if j not in missing]
        t = make_track(int(rng.integers(1, 2**63)), TrackState(int(rng.integers(0, 4))),
                       missing, predicted, nan_pos=bool(rng.random() < 0.3), rng=rng)
        t.velocity = np.array([np.nan, 0, 0]) if rng.random() < 0.3 else rng.normal(0, 1, 3)
        tracks.append(t)
    opts = MarkerOptions(ns=['mv3dpose', 'ünï/çode'][seed % 2], show_velocity=seed % 3 > 0,
                         show_labels=seed % 4 > 0, lifetime_s=float(rng.uniform(0, 3)))
    h = Header(frame_id=['map', 'wörld_🙂'][seed % 2])
    h.stamp.sec, h.stamp.nanosec = int(rng.integers(0, 2**31)), int(rng.integers(0, 10**9))
    data = tracks_to_markers_cdr(tracks, LAYOUT.bones, h, opts)
    assert isinstance(data, bytes)
    got = message_to_dict(deserialize_message(data, MarkerArray))
    want = message_to_dict(deserialize_message(
        serialize_message(tracks_to_markers(tracks, LAYOUT.bones, h, opts)), MarkerArray))
    assert got == want
    assert len(got['markers']) >= 4
