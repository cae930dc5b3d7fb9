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
pose2d_node's inference rate: the grid, the parameter, auto mode across a rig, over real DDS.

The grid keeps the cameras of a rig on the same instants; the images between its windows are
not copied out of DDS and are announced on persons_2d/skipped; auto-mode cameras follow the
slowest one announced. The mailbox's and the rate's own arithmetic is ``test_pose2d_parts``'s.
"""

import os
import time

from mv3dpose_msgs.msg import Person2DArray, SkippedImages
from mv3dpose_ros.ros.images import numpy_to_image
from mv3dpose_ros.ros.messages import ns_to_stamp, stamp_to_ns
from mv3dpose_ros.ros.qos import reliable_qos
from mv3dpose_ros.testing.spin import spin_until
import numpy as np
from pose2d_models import crafted_model, H, W
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from sensor_msgs.msg import Image
from std_msgs.msg import Header

pytestmark = [pytest.mark.ros]

NS = 1_000_000_000
REMAP = ['--ros-args', '-r', 'image:=image_raw']


def test_inference_rate_grid_keeps_cameras_on_the_same_instants(ros_context):
    """inference_rate_hz: only the first image of each stamp window reaches the model."""
    from mv3dpose_ros.nodes.pose2d.node import header_stamp_ns, Pose2DNode
    from rclpy.serialization import serialize_message
    nodes = [Pose2DNode(context=ros_context, namespace=f'/grid{i}', parameter_overrides=[
        Parameter('autostart', value=False), Parameter('inference_rate_hz', value=5.0)])
        for i in range(2)]
    img = np.zeros((4, 4, 3), np.uint8)
    try:
        taken = [[], []]
        for i, node in enumerate(nodes):
            # camera 1 misses some frames and receives them with jitter: same instants anyway
            steps = range(0, 20) if i == 0 else (1, 2, 5, 6, 7, 9, 12, 13, 17, 18, 19)
            for k in steps:
                stamp = 1000 * NS + k * 50_000_000             # 20 Hz camera
                wire = serialize_message(numpy_to_image(
                    img, Header(stamp=ns_to_stamp(stamp), frame_id='f'), 'bgr8'))
                assert header_stamp_ns(wire) == stamp
                before = node.stats.skipped
                node.offer(wire)
                if node.stats.skipped == before:
                    taken[i].append(stamp)
        assert [t - 1000 * NS for t in taken[0]] == [k * 200_000_000 for k in range(5)]
        counts = nodes[0].stats
        assert counts.skipped == 15 and counts.received == 20
        assert counts.dropped == 4                  # no worker: each replaced the previous
        # camera 1 took the first image it had of each window: where it had the window's
        # first frame (600 ms), both cameras infer the same instant
        assert [t - 1000 * NS for t in taken[1]] == [ms * 1_000_000 for ms in
                                                     (50, 250, 450, 600, 850)]
        assert set(taken[0]) & set(taken[1]) == {1000 * NS + 600_000_000}
        # a stamp jump back (a replay starting again) opens a new window at once
        back = serialize_message(numpy_to_image(
            img, Header(stamp=ns_to_stamp(990 * NS), frame_id='f'), 'bgr8'))
        nodes[0].offer(back)
        assert nodes[0].stats.waiting_stamp_ns == 990 * NS       # it waits for the model
        assert not nodes[0].set_parameters([Parameter('inference_rate_hz', value=2000.0)])[
            0].successful
        nodes[0].set_parameters([Parameter('inference_rate_hz', value=0.0)])
        nodes[0].offer(back)
        assert nodes[0].stats.skipped == 15          # 0 = every image reaches the mailbox
    finally:
        for node in nodes:
            node.destroy_node()


def test_grid_mode_takes_few_images_infers_each_window_first_and_announces_the_rest(
        tmp_path, ros_context):
    """
    Real DDS: a 20 Hz camera, a 2 Hz grid; the images between windows are not copied.

    Each window's first image is inferred and the nine after it are not, so every
    Person2DArray follows a SkippedImages (persons_2d/skipped) from the one before (0 first):
    no Person2DArray is stamped inside an announced gap.
    """
    from mv3dpose_ros.nodes.pose2d.node import Pose2DNode
    model, _ = crafted_model(tmp_path)
    node = Pose2DNode(context=ros_context, namespace='/lazy', cli_args=REMAP,
                      parameter_overrides=[
                          Parameter('model.path', value=model),
                          Parameter('model.threads', value=1),
                          Parameter('image_qos.reliability', value='reliable'),
                          Parameter('inference_rate_hz', value=2.0),
                          Parameter('rig_rate_topic', value='')])
    probe = rclpy.create_node('lazy_probe', context=ros_context)
    stamps, notes = [], []
    probe.create_subscription(Person2DArray, '/lazy/persons_2d',
                              lambda m: stamps.append(stamp_to_ns(m.header.stamp)),
                              reliable_qos(50))
    probe.create_subscription(SkippedImages, '/lazy/persons_2d/skipped',
                              lambda m: notes.append((stamp_to_ns(m.after),
                                                      stamp_to_ns(m.header.stamp), m.camera_id)),
                              reliable_qos(50))
    pub = probe.create_publisher(Image, '/lazy/image_raw', reliable_qos(5))
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(node)
    ex.add_node(probe)
    img = np.zeros((H, W, 3), np.uint8)
    try:
        assert node.active
        assert spin_until(ex, lambda: pub.get_subscription_count() > 0, 10.0)
        base = (time.time_ns() // NS + 2) * NS       # stamps on a 50 ms grid from a 500 ms one
        t0 = time.monotonic()
        for k in range(80):                          # 4 s of a 20 Hz camera, paced in real time
            pub.publish(numpy_to_image(img, Header(stamp=ns_to_stamp(base + k * 50_000_000),
                                                   frame_id='f'), 'bgr8'))
            while time.monotonic() < t0 + (k + 1) * 0.05:
                ex.spin_once(timeout_sec=0.01)
        assert spin_until(ex, lambda: node.stats.received >= 80, 5.0), node.stats
        spin_until(ex, lambda: False, 0.5)
        # each window of 10 images is inferred from its first one
        assert len(stamps) >= 6, stamps
        assert all((s - base) % 500_000_000 == 0 for s in stamps), [s - base for s in stamps]
        # and only about two of its ten images are copied out of DDS
        counts = node.stats
        assert counts.taken <= counts.received // 2, counts
        assert counts.skipped + counts.processed + counts.dropped == counts.received
        assert notes == [(prev, cur, 'lazy') for prev, cur in zip([0] + stamps, stamps)], \
            (notes, stamps)
        assert counts.skips_announced == len(notes)
    finally:
        ex.shutdown()
        node.destroy_node()
        probe.destroy_node()


def test_auto_cameras_of_a_rig_follow_the_slowest_announced_rate(tmp_path, ros_context):
    """Two auto-mode nodes announce their rates and take a slower camera's; fixed ones not."""
    from mv3dpose_ros.nodes.pose2d.node import Pose2DNode
    from std_msgs.msg import Float64
    model, _ = crafted_model(tmp_path)
    topic = f'/test_rig_rate_{os.getpid()}'
    nodes = [Pose2DNode(context=ros_context, namespace=f'/rig{k}', parameter_overrides=[
        Parameter('model.path', value=model), Parameter('model.threads', value=1),
        Parameter('rig_rate_topic', value=topic),
        Parameter('inference_rate_hz', value='auto' if k < 2 else 1.0)]) for k in range(3)]
    probe = rclpy.create_node('rig_rate_probe', context=ros_context)
    heard = []
    probe.create_subscription(Float64, topic, lambda m: heard.append(m.data), reliable_qos(10))
    slow = probe.create_publisher(Float64, topic, reliable_qos(10))
    ex = SingleThreadedExecutor(context=ros_context)
    for n in nodes + [probe]:
        ex.add_node(n)
    auto = nodes[:2]
    try:
        assert all(n.active for n in nodes)
        # each auto node announces its own choice (every image: 0) once a second
        assert spin_until(ex, lambda: len(heard) >= 2, 10.0) and set(heard) == {0.0}
        assert all(n.stats.inference_rate_hz == 0.0 for n in auto)
        slow.publish(Float64(data=float('nan')))          # malformed: ignored
        slow.publish(Float64(data=2.5))                   # a slower camera of the rig
        assert spin_until(ex, lambda: all(n.stats.inference_rate_hz == 2.5 for n in auto), 5.0)
        assert nodes[2].stats.inference_rate_hz == 1.0          # a fixed rate is the user's
        # the slow camera goes silent: after the TTL every auto node is on its own again
        assert spin_until(ex, lambda: all(n.stats.inference_rate_hz == 0.0 for n in auto), 10.0)
        assert nodes[2].stats.inference_rate_hz == 1.0
    finally:
        ex.shutdown()
        for n in nodes + [probe]:
            n.destroy_node()


def test_inference_rate_parameter_accepts_auto_int_and_float(ros_context):
    from mv3dpose_ros.nodes.pose2d.node import parse_inference_rate, Pose2DNode
    assert parse_inference_rate('auto') == -1.0 and parse_inference_rate(-1) == -1.0
    assert parse_inference_rate(1) == 1.0 and parse_inference_rate('2.5') == 2.5
    for bad in ('fast', 1e6, float('nan'), True):
        with pytest.raises(ValueError, match='inference_rate_hz'):
            parse_inference_rate(bad)
    node = Pose2DNode(context=ros_context, namespace='/rate', parameter_overrides=[
        Parameter('autostart', value=False)])
    try:
        assert node.stats.rate_mode == 'auto' and node.stats.inference_rate_hz == 0.0  # default
        assert node.set_parameters([Parameter('inference_rate_hz', value=1)])[0].successful
        assert node.stats.rate_mode != 'auto' and node.stats.inference_rate_hz == 1.0
        assert node.set_parameters([Parameter('inference_rate_hz', value='auto')])[0].successful
        assert node.stats.rate_mode == 'auto'
        res = node.set_parameters([Parameter('inference_rate_hz', value='often')])[0]
        assert not res.successful and 'inference_rate_hz' in res.reason
        assert node.set_parameters([Parameter('inference_rate_hz', value=0)])[0].successful
        assert node.stats.rate_mode != 'auto' and node.stats.inference_rate_hz == 0.0
    finally:
        node.destroy_node()
    bad = Pose2DNode(context=ros_context, namespace='/rate2', parameter_overrides=[
        Parameter('inference_rate_hz', value='often')])
    try:
        assert not bad.active and 'inference_rate_hz' in bad.error
    finally:
        bad.destroy_node()
