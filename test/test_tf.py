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
TF of fusion_node: frames maths, and the tf2_ros code path against a fake ``tf2_ros`` module.

tf2_ros is not in the PyPI wheels, so a module with its four classes (``Buffer``,
``TransformListener``, ``StaticTransformBroadcaster``, ``TransformBroadcaster``) and its
exception is put in ``sys.modules['tf2_ros']``, where ``import tf2_ros`` finds it exactly as it
would find the real one. The node is the real ``FusionNode`` fed with the real Pose2Sim
detections over DDS; what reaches the fake broadcasters is checked against the rig and against
``~/tracks``.
"""

import math
import sys
import time
import types

from geometry_msgs.msg import Quaternion, TransformStamped
from mv3dpose_msgs.msg import Person2DArray, TrackedSkeletonArray
from mv3dpose_ros.core.geometry.calibration import quaternion_to_matrix
from mv3dpose_ros.core.skeleton import get_layout
from mv3dpose_ros.core.types import JointState, Track, TrackState
from mv3dpose_ros.ros.frames import (body_yaw, camera_from_transform, camera_transforms, Headings,
                                     optical_frame, pose_array_cdr, quaternion_from_yaw,
                                     root_pose_array, root_poses, track_transforms,
                                     yaw_from_quaternion)
from mv3dpose_ros.ros.messages import msg_to_tracks, stamp_to_ns
from mv3dpose_ros.ros.qos import reliable_qos
from mv3dpose_ros.testing.spin import spin_until
import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from real_feed import Pose2Sim
from std_msgs.msg import Header

LAYOUT = get_layout('coco17')


# ------------------------------------------------------------------------------ fake tf2_ros
class FakeTransformException(Exception):
    """tf2_ros.TransformException."""


class FakeLookupException(FakeTransformException):
    """tf2_ros.LookupException."""


class FakeStaticTransformBroadcaster:
    """Record what a node sends, checking the argument types tf2_ros accepts."""

    instances = []

    def __init__(self, node, qos=None):
        assert hasattr(node, 'create_publisher'), 'tf2_ros broadcasters take the node'
        self.sent = []
        self.instances.append(self)

    def sendTransform(self, transform):  # noqa: N802 - the tf2_ros method name
        transforms = transform if isinstance(transform, list) else [transform]
        assert all(isinstance(t, TransformStamped) for t in transforms)
        self.sent.append(list(transforms))


class FakeTransformBroadcaster(FakeStaticTransformBroadcaster):
    """tf2_ros.TransformBroadcaster."""

    instances = []


class FakeBuffer:
    """A tf2 buffer holding ``FakeBuffer.transforms[(target, source)]``."""

    transforms = {}

    def can_transform(self, target, source, time, timeout=None):
        return (target, source) in self.transforms

    def lookup_transform(self, target, source, time, timeout=None):
        if (target, source) not in self.transforms:
            raise FakeLookupException(f'"{source}" passed to lookupTransform argument '
                                      f'source_frame does not exist.')
        return self.transforms[(target, source)]


class FakeTransformListener:
    """tf2_ros.TransformListener(buffer, node, spin_thread=...)."""

    instances = []

    def __init__(self, buffer, node, *, spin_thread=True, qos=None, static_qos=None):
        assert isinstance(buffer, FakeBuffer) and hasattr(node, 'create_subscription')
        self.spin_thread = spin_thread
        self.node = node
        self.instances.append(self)


@pytest.fixture
def fake_tf2(monkeypatch):
    mod = types.ModuleType('tf2_ros')
    mod.Buffer = FakeBuffer
    mod.TransformListener = FakeTransformListener
    mod.StaticTransformBroadcaster = FakeStaticTransformBroadcaster
    mod.TransformBroadcaster = FakeTransformBroadcaster
    mod.TransformException = FakeTransformException
    mod.LookupException = FakeLookupException
    for cls in (FakeStaticTransformBroadcaster, FakeTransformBroadcaster,
                FakeTransformListener):
        monkeypatch.setattr(cls, 'instances', [])
    monkeypatch.setattr(FakeBuffer, 'transforms', {})
    monkeypatch.setitem(sys.modules, 'tf2_ros', mod)
    return mod


@pytest.fixture
def no_tf2(monkeypatch):
    monkeypatch.setitem(sys.modules, 'tf2_ros', None)   # import tf2_ros raises ImportError


# ------------------------------------------------------------------------------ frames maths
def _person(track_id, root, yaw, state=TrackState.CONFIRMED, hips=True, velocity=(0, 0, 0)):
    """Return a coco17 track standing at ``root`` facing ``yaw`` (hips 0.3 m apart)."""
    J = LAYOUT.num_joints
    joints = np.full((J, 3), np.nan)
    left, right = LAYOUT.root_joints
    side = 0.15 * np.array([-math.sin(yaw), math.cos(yaw), 0.0])     # body y (left) axis
    states = np.zeros(J, np.uint8)
    if hips:
        joints[left], joints[right] = np.add(root, side), np.subtract(root, side)
        states[[left, right]] = JointState.TRIANGULATED
    joints[0] = np.add(root, [0, 0, 0.7])
    states[0] = JointState.TRIANGULATED
    return Track(track_id=track_id, state=state, joints=joints, confidence=np.ones(J),
                 joint_state=states, num_views=np.full(J, 3, np.uint8),
                 reprojection_error=np.zeros(J), position=np.asarray(root, float),
                 velocity=np.asarray(velocity, float), first_seen=0.0, last_observed=0.0)


@pytest.mark.parametrize('yaw', [0.0, 0.5 * math.pi, -2.0, 3.0])
def test_body_yaw_from_hips_is_the_facing_direction(yaw):
    got = body_yaw(_person(1, [1.0, 2.0, 0.9], yaw), LAYOUT)
    assert math.isclose(math.remainder(got - yaw, 2 * math.pi), 0.0, abs_tol=1e-9)
    q = quaternion_from_yaw(got)
    # the body x axis (forward) is perpendicular to the hips, z stays up
    R = quaternion_to_matrix([q.x, q.y, q.z, q.w])
    np.testing.assert_allclose(R[:, 0], [math.cos(yaw), math.sin(yaw), 0], atol=1e-9)
    np.testing.assert_allclose(R[:, 2], [0, 0, 1], atol=1e-12)
    assert math.isclose(yaw_from_quaternion(q), math.remainder(yaw, 2 * math.pi), abs_tol=1e-9)


def test_heading_without_hips_from_motion_then_memory():
    moving = _person(3, [0, 0, 1], 0.0, hips=False, velocity=(0.0, -1.2, 0.0))
    assert math.isclose(body_yaw(moving, LAYOUT), -0.5 * math.pi)
    still = _person(3, [0, 0, 1], 0.0, hips=False)
    assert body_yaw(still, LAYOUT) is None
    headings = Headings(LAYOUT)
    assert headings.update([_person(3, [0, 0, 1], 1.0)]) == [pytest.approx(1.0)]
    assert headings.update([still]) == [pytest.approx(1.0)]          # kept while hips unseen
    dead = _person(3, [0, 0, 1], 1.0, state=TrackState.DELETED)
    assert headings.update([dead]) == [None]
    assert headings.update([still]) == [None]                         # forgotten once deleted


def test_camera_transforms_are_the_rig_poses_and_invert(shared_data):
    feed = Pose2Sim(shared_data, frames=1)
    header = Header(frame_id='map')
    tfs = camera_transforms(feed.cameras, header)
    assert [t.child_frame_id for t in tfs] == [optical_frame(c) for c in feed.cameras]
    assert optical_frame('00_03') == 'cam00_03_optical_frame'       # ROS name of the camera
    X = np.array([0.3, -0.2, 1.1])                                   # a point in the world
    for tf, (name, cam) in zip(tfs, feed.cameras.items()):
        assert tf.header.frame_id == 'map'
        r, p = tf.transform.rotation, tf.transform.translation
        R_wc = quaternion_to_matrix([r.x, r.y, r.z, r.w])
        # world <- optical frame: maps the point's camera coordinates back to the world
        np.testing.assert_allclose(R_wc @ cam.to_camera(X[None])[0] + [p.x, p.y, p.z], X,
                                   atol=1e-9)
        back = camera_from_transform(cam, tf)
        np.testing.assert_allclose(back.project(X[None]), cam.project(X[None]), atol=1e-6)
    bad = camera_transforms(feed.cameras, header)[0]
    bad.transform.rotation = Quaternion(x=0.0, y=0.0, z=0.0, w=2.0)
    with pytest.raises(ValueError, match='not a unit quaternion'):
        camera_from_transform(feed.cameras['cam_01'], bad)


def test_track_frames_and_pose_array_skip_tentative_deleted_and_rootless():
    tracks = [_person(1, [1, 2, 0.9], 0.3), _person(2, [0, 0, 1], 1.0, TrackState.TENTATIVE),
              _person(4, [3, 1, 0.9], -1.0, TrackState.COASTING),
              _person(5, [0, 0, 0], 0.0, TrackState.DELETED)]
    rootless = _person(6, [0, 0, 0], 0.0)
    rootless.position = np.full(3, np.nan)
    tracks.append(rootless)
    header = Header(frame_id='map')
    yaws = Headings(LAYOUT).update(tracks)
    tfs = track_transforms(tracks, yaws, header, 'body_')
    assert [t.child_frame_id for t in tfs] == ['body_1', 'body_4']
    assert tfs[0].transform.translation.x == 1.0 and tfs[0].transform.translation.z == 0.9
    assert math.isclose(yaw_from_quaternion(tfs[1].transform.rotation), -1.0)
    poses = root_pose_array(tracks, yaws, header)
    # every non-deleted track with a root, in ~/tracks order (TENTATIVE included when published)
    assert [(p.position.x, p.position.y) for p in poses.poses] == [(1, 2), (0, 0), (3, 1)]
    assert poses.header is header
    # the node publishes the same as CDR bytes
    from geometry_msgs.msg import PoseArray
    from rclpy.serialization import deserialize_message
    header.stamp.sec, header.stamp.nanosec = 12, 345
    cdr = pose_array_cdr(root_poses(tracks, yaws), header)
    assert deserialize_message(cdr, PoseArray) == root_pose_array(tracks, yaws, header)
    empty = pose_array_cdr(root_poses([], []), header)
    assert deserialize_message(empty, PoseArray) == PoseArray(header=header)


# ------------------------------------------------------------------------------ the node
class NodeRun:
    """A real FusionNode plus a probe in one context; the probe publishes Pose2Sim frames."""

    def __init__(self, shared_data, **params):
        from mv3dpose_ros.nodes.fusion.node import FusionNode
        self.feed = Pose2Sim(shared_data, frames=30)
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx)
        overrides = {'rig_config': self.feed.rig_path, 'layout': 'body25b',
                     'world_frame': 'map', 'sync.max_wait_s': 2.0}   # loaded hosts
        overrides.update(params)
        try:
            self.node = FusionNode(context=self.ctx, parameter_overrides=[
                Parameter(k, value=v) for k, v in overrides.items()])
        except BaseException:
            rclpy.shutdown(context=self.ctx)
            raise

    def start_probe(self):
        self.probe = rclpy.create_node('tf_probe', context=self.ctx)
        self.pubs = {c: self.probe.create_publisher(Person2DArray, f'/{c}/persons_2d',
                                                    reliable_qos(100))
                     for c in self.feed.cameras}
        self.tracks = []
        self.probe.create_subscription(TrackedSkeletonArray, '/fusion_node/tracks',
                                       self.tracks.append, reliable_qos(100))
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self.executor.add_node(self.probe)
        assert self.spin_until(lambda: all(p.get_subscription_count()
                                           for p in self.pubs.values()))

    def spin_until(self, predicate, timeout=10.0):
        return spin_until(self.executor, predicate, timeout)

    def play(self):
        for i in range(len(self.feed.frames)):
            for cam, msg in self.feed.messages(i):
                self.pubs[cam].publish(msg)
            assert self.spin_until(lambda: len(self.tracks) > i), f'no output for frame {i}'

    def close(self):
        if hasattr(self, 'executor'):
            self.executor.shutdown()
            self.probe.destroy_node()
        self.node.destroy_node()
        rclpy.shutdown(context=self.ctx)


@pytest.fixture
def node_run(shared_data):
    runs = []

    def make(**params):
        run = NodeRun(shared_data, **params)
        runs.append(run)
        return run

    yield make
    for run in runs:
        run.close()


@pytest.mark.ros
def test_node_publishes_static_camera_poses_and_track_frames(fake_tf2, node_run):
    run = node_run(**{'tf.publish_tracks': True})
    [static] = FakeStaticTransformBroadcaster.instances
    [sent] = static.sent                                 # once, at start, all cameras
    expected = camera_transforms(run.feed.cameras, Header(frame_id='map'))
    assert [t.child_frame_id for t in sent] == [t.child_frame_id for t in expected]
    for got, want in zip(sent, expected):
        assert got.header.frame_id == 'map'
        assert got.transform == want.transform
    assert not FakeTransformListener.instances           # no lookups with extrinsics: rig
    run.start_probe()
    run.play()
    [dynamic] = FakeTransformBroadcaster.instances
    by_stamp = {}
    for batch in dynamic.sent:
        stamps = {stamp_to_ns(t.header.stamp) for t in batch}
        assert len(stamps) == 1 and batch[0].header.frame_id == 'map'
        by_stamp[stamps.pop()] = {t.child_frame_id: t for t in batch}
    checked = turned = 0
    for msg in run.tracks:
        confirmed = [t for t in msg_to_tracks(msg)
                     if t.state in (TrackState.CONFIRMED, TrackState.COASTING)]
        frames = by_stamp.get(stamp_to_ns(msg.header.stamp), {})
        assert sorted(frames) == sorted(f'body_{t.track_id}' for t in confirmed)
        for t in confirmed:
            tf = frames[f'body_{t.track_id}'].transform
            np.testing.assert_allclose([tf.translation.x, tf.translation.y, tf.translation.z],
                                       t.position, atol=1e-9)
            yaw = body_yaw(t, get_layout('body25b'))      # from the published joints
            if yaw is not None:
                assert math.isclose(math.remainder(
                    yaw_from_quaternion(tf.rotation) - yaw, 2 * math.pi), 0.0, abs_tol=1e-4)
                turned += 1
            checked += 1
    assert checked >= 40, f'only {checked} track frames checked (2 people x 30 frames)'
    assert turned >= 0.8 * checked, f'heading from the hips in only {turned} of {checked}'


@pytest.mark.ros
def test_extrinsics_from_tf_replace_the_rig_poses(fake_tf2, node_run, shared_data):
    feed = Pose2Sim(shared_data, frames=1)
    # The "URDF" places cam_02 10 cm higher than the rig file does.
    for tf in camera_transforms(feed.cameras, Header(frame_id='map')):
        if tf.child_frame_id == 'cam_02_optical_frame':
            tf.transform.translation.z += 0.1
        FakeBuffer.transforms[('map', tf.child_frame_id)] = tf
    run = node_run(extrinsics_source='tf')
    [listener] = FakeTransformListener.instances
    assert listener.spin_thread is False and listener.node is not run.node
    assert not FakeStaticTransformBroadcaster.instances  # poses come from TF: not re-published
    for name, cam in feed.cameras.items():
        shift = [0, 0, 0.1] if name == 'cam_02' else [0, 0, 0]
        np.testing.assert_allclose(run.node.rig[name].center, cam.center + shift, atol=1e-9)
        np.testing.assert_allclose(run.node.rig[name].K, cam.K)


@pytest.mark.ros
def test_extrinsics_from_tf_missing_frame_is_a_clear_config_error(
        fake_tf2, node_run, shared_data):
    from mv3dpose_ros.nodes.fusion.node import ConfigError
    feed = Pose2Sim(shared_data, frames=1)
    for tf in camera_transforms(feed.cameras, Header(frame_id='map')):
        if tf.child_frame_id != 'cam_03_optical_frame':
            FakeBuffer.transforms[('map', tf.child_frame_id)] = tf
    t0 = time.monotonic()
    with pytest.raises(ConfigError, match='map -> cam_03_optical_frame within 0.3 s'):
        node_run(extrinsics_source='tf', **{'tf.lookup_timeout_s': 0.3})
    assert time.monotonic() - t0 < 20.0


@pytest.mark.ros
def test_without_tf2_the_node_runs_and_says_once_that_tf_is_off(no_tf2, node_run, capfd):
    run = node_run(**{'tf.publish_tracks': True})
    assert not run.node.tf.enabled
    run.start_probe()
    run.play()
    assert len(run.tracks) == 30
    err = capfd.readouterr()
    assert (err.out + err.err).count('TF is off') == 1


@pytest.mark.ros
def test_without_tf2_extrinsics_from_tf_is_refused(no_tf2, node_run):
    from mv3dpose_ros.nodes.fusion.node import ConfigError
    with pytest.raises(ConfigError, match='tf2_ros is not importable'):
        node_run(extrinsics_source='tf')
