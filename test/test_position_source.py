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
A track whose hip is unknown: its root is the body centre, said so on every output.

``~/tracks`` (``TrackedSkeleton.position_source``), ``~/poses``, the TF frames and the
fixed-lag smoother never put such a track at the origin; a track with no position at all gets
no pose and no frame.
"""

import dataclasses

from geometry_msgs.msg import PoseArray
from mv3dpose_msgs.msg import TrackedSkeleton, TrackedSkeletonArray
from mv3dpose_ros.core.fusion.pipeline import Fusion
from mv3dpose_ros.core.tracking.smoothing import FixedLagSmoother, smooth_track_sequence
from mv3dpose_ros.core.types import JointState, PositionSource, TrackState
from mv3dpose_ros.ros.frames import Headings, pose_array_cdr, root_poses, track_transforms
from mv3dpose_ros.ros.messages import msg_to_tracks, ns_to_stamp, tracks_to_cdr
from mv3dpose_ros.sim.scene import make_scene
import numpy as np
import pytest
from rclpy.serialization import deserialize_message
from std_msgs.msg import Header

HIP_LOST_AT = 10          # from this set on no camera sees the left hip


@pytest.fixture(scope='module')
def run():
    """Return ``(layout, outputs)``: two people, 4 cameras, the left hip unseen from set 10."""
    scene = make_scene(num_cameras=4, num_people=2, num_frames=25, seed=5)
    fusion = Fusion(scene.cameras, scene.layout)
    left, _ = fusion.layout.root_joints
    outputs = []
    for k, (stamp, views) in enumerate(scene.frames()):
        if k >= HIP_LOST_AT:
            views = {cam: v.copy() for cam, v in views.items()}
            for v in views.values():
                v[:, left, 2] = 0.0                     # not detected
        outputs.append((stamp, fusion.step(views, stamp)))
    return fusion.layout, outputs


def _live(tracks):
    return [t for t in tracks if t.state in (TrackState.CONFIRMED, TrackState.COASTING)]


def test_missing_hip_gives_a_body_root_with_a_wider_covariance(run):
    layout, outputs = run
    left, right = layout.root_joints
    before = _live(outputs[HIP_LOST_AT - 1][1])
    after = _live(outputs[-1][1])
    assert len(before) == len(after) == 2
    assert all(t.position_source == PositionSource.HIPS for t in before)
    hips_var = max(t.position_covariance[0, 0] for t in before)
    for t in after:
        assert t.joint_state[left] == JointState.MISSING
        assert t.position_source == PositionSource.BODY
        centre = np.nanmean(t.joints, axis=0)
        assert np.isfinite(t.position).all() and np.linalg.norm(t.position - centre) < 0.15
        assert t.position_covariance[0, 0] > max(hips_var, 0.15 ** 2)

    stamp, tracks = outputs[-1]
    header = Header(stamp=ns_to_stamp(round(stamp * 1e9)), frame_id='world')
    msg = deserialize_message(tracks_to_cdr(tracks, header, layout.name), TrackedSkeletonArray)
    published = [s for s in msg.skeletons if s.state in (TrackedSkeleton.CONFIRMED,
                                                         TrackedSkeleton.COASTING)]
    assert len(published) == 2
    for s, t in zip(published, after):
        assert s.track_id == t.track_id
        assert s.position_source == TrackedSkeleton.POSITION_BODY
        xyz = np.array([s.position.x, s.position.y, s.position.z])
        np.testing.assert_array_equal(xyz, t.position)
        assert np.linalg.norm(xyz) > 0.5                   # a person, not the origin
        assert s.position_covariance[0] == t.position_covariance[0, 0] > 0.15 ** 2
    back = msg_to_tracks(msg)
    assert [t.position_source for t in back] == [t.position_source for t in tracks]


def test_body_root_is_published_on_poses_and_tf_never_at_the_origin(run):
    layout, outputs = run
    stamp, tracks = outputs[-1]
    tracks = list(tracks)
    rootless = _live(tracks)[0]
    rootless = dataclasses.replace(rootless, track_id=999, position=np.full(3, np.nan),
                                   position_source=PositionSource.NONE)
    claimed = dataclasses.replace(rootless, track_id=1000, position=np.zeros(3))
    tracks += [rootless, claimed]           # NONE with a (meaningless) origin: still skipped
    header = Header(stamp=ns_to_stamp(round(stamp * 1e9)), frame_id='world')
    yaws = Headings(layout).update(tracks)
    body = [t for t in _live(tracks) if t.position_source == PositionSource.BODY]
    assert len(body) == 2

    frames = track_transforms(tracks, yaws, header, 'body_')
    assert [f.child_frame_id for f in frames] == [f'body_{t.track_id}' for t in body]
    for f, t in zip(frames, body):
        xyz = f.transform.translation
        assert [xyz.x, xyz.y, xyz.z] == t.position.tolist()

    poses = deserialize_message(pose_array_cdr(root_poses(tracks, yaws), header), PoseArray)
    rows = [[p.position.x, p.position.y, p.position.z] for p in poses.poses]
    want = [t.position.tolist() for t in tracks
            if t.state != TrackState.DELETED and t.position_source != PositionSource.NONE]
    assert rows == want and len(rows) >= 2
    assert all(np.linalg.norm(r) > 0.5 for r in rows)

    msg = deserialize_message(tracks_to_cdr(tracks, header, layout.name), TrackedSkeletonArray)
    for s in msg.skeletons[-2:]:                        # said so, not a silent origin
        assert s.position_source == TrackedSkeleton.POSITION_NONE
        assert s.position_covariance[0] == -1.0


def test_fixed_lag_smoother_keeps_the_body_root(run):
    layout, outputs = run
    smoother = FixedLagSmoother(lag=2, root_joints=layout.root_joints)
    sets = [smoother.push(k, stamp, tracks) for k, (stamp, tracks) in enumerate(outputs)]
    sets = [s for s in sets if s is not None] + smoother.flush()
    assert len(sets) == len(outputs)
    hips = _live(sets[HIP_LOST_AT - 3][2])
    assert hips and all(t.position_source == PositionSource.HIPS for t in hips)
    body = 0
    for (_, live), (_, _, smoothed) in zip(outputs, sets):
        for t, s in zip(_live(live), _live(smoothed)):
            assert s.track_id == t.track_id and np.isfinite(s.position).all()
            if t.position_source != PositionSource.BODY:    # the hip still held by the filter
                continue
            body += 1
            assert s.position_source == PositionSource.BODY
            np.testing.assert_array_equal(s.position, t.position)
            assert s.position_covariance[0, 0] > 0.15 ** 2
    assert body >= 4


def test_batch_smoothing_keeps_the_body_root(run):
    layout, outputs = run
    frames = smooth_track_sequence([tracks for _, tracks in outputs], max_gap_frames=3,
                                   root_joints=layout.root_joints)
    live, smoothed = _live(outputs[-1][1]), _live(frames[-1])
    assert [t.position_source for t in live] == [PositionSource.BODY] * 2
    for t, s in zip(live, smoothed):
        assert s.position_source == PositionSource.BODY
        np.testing.assert_array_equal(s.position, t.position)
    assert all(t.position_source == PositionSource.HIPS for t in _live(frames[2]))


def test_bag_typestore_reads_the_field(run):
    """Bags and the Foxglove schema take the type from the .msg files: the field is there."""
    from mv3dpose_ros.io.bag import get_typestore
    layout, outputs = run
    stamp, tracks = outputs[-1]
    header = Header(stamp=ns_to_stamp(round(stamp * 1e9)), frame_id='world')
    store = get_typestore()
    msg = store.deserialize_cdr(tracks_to_cdr(tracks, header, layout.name),
                                'mv3dpose_msgs/msg/TrackedSkeletonArray')
    assert [s.position_source for s in msg.skeletons] == [int(t.position_source)
                                                          for t in tracks]
    text, _ = store.generate_msgdef('mv3dpose_msgs/msg/TrackedSkeletonArray', ros_version=2)
    assert 'uint8 position_source' in text and 'POSITION_BODY' in text
