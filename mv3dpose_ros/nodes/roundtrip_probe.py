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
A publish/echo probe for mv3dpose_msgs over real DDS, used by the round-trip tests.

``roundtrip_probe publish --type person2d --count 5`` publishes deterministic sample messages
until ``count`` subscribers' worth of delivery is confirmed; ``roundtrip_probe echo --type
person2d --count 5 --output out.json`` writes the fields of what it received as JSON.
Both sides build the same samples from ``sample_message(kind, index)``.
"""

import argparse
import json
import sys
import time
from typing import Any, List, Optional

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, Vector3
from mv3dpose_msgs.msg import (Joint3D, Keypoint2D, Person2D, Person2DArray, TrackedSkeleton,
                               TrackedSkeletonArray)
from mv3dpose_ros.ros.messages import float32_exact, message_to_dict
import numpy as np
import rclpy
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import RegionOfInterest
from std_msgs.msg import Header

TYPES = {'person2d': Person2DArray, 'tracks': TrackedSkeletonArray}
TOPIC = '/mv3dpose_probe/{}'
# Reliable and transient-local, so a late subscriber still gets every sample.
QOS = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                 durability=DurabilityPolicy.TRANSIENT_LOCAL)


def sample_message(kind: str, index: int) -> Any:
    """Build the deterministic sample ``index`` of ``kind``; every field gets a non-default."""
    rng = np.random.default_rng(1000 + index)
    header = Header(stamp=Time(sec=1700000000 + index, nanosec=int(rng.integers(1e9))),
                    frame_id=f'frame_{index}')
    if kind == 'person2d':
        persons = []
        for p in range(1 + index % 3):
            kps = [Keypoint2D(x=x, y=y, confidence=c) for x, y, c in zip(
                float32_exact(rng.uniform(0, 1920, 17)), float32_exact(rng.uniform(0, 1080, 17)),
                float32_exact(rng.uniform(0, 1, 17)))]
            persons.append(Person2D(
                roi=RegionOfInterest(x_offset=int(rng.integers(100)), y_offset=p + 1,
                                     height=200 + p, width=100 + p, do_rectify=False),
                score=float32_exact([rng.uniform()])[0], id=f'p{p}', keypoints=kps))
        return Person2DArray(header=header, camera_id=f'cam{index}', image_width=1920,
                             image_height=1080, layout='coco17', persons=persons)
    skeletons = []
    for t in range(1 + index % 3):
        joints = [Joint3D(position=Point(x=float(a), y=float(b), z=float(c)),
                          confidence=float32_exact([rng.uniform()])[0], state=j % 3,
                          num_views=j % 5, reprojection_error=float32_exact([j * 0.5])[0])
                  for j, (a, b, c) in enumerate(rng.normal(size=(17, 3)))]
        skeletons.append(TrackedSkeleton(
            track_id=2**40 + 10 * index + t, state=t % 4, confidence=0.25 * (t + 1),
            first_seen=Time(sec=10 + t, nanosec=5), last_observed=Time(sec=20 + t, nanosec=7),
            age=100 + t, missed=t, position=Point(x=1.5, y=-2.0, z=0.9 + t),
            velocity=Vector3(x=0.1, y=0.2, z=-0.3), velocity_valid=bool(t % 2),
            position_covariance=[float(v) for v in range(9)], position_source=t % 3,
            joints=joints, source_cameras=[f'cam{c}' for c in range(t + 2)]))
    return TrackedSkeletonArray(header=header, layout='coco17', skeletons=skeletons)


def _publish(node, kind: str, count: int, timeout: float) -> int:
    pub = node.create_publisher(TYPES[kind], TOPIC.format(kind), QOS)
    deadline = time.monotonic() + timeout
    while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
    if pub.get_subscription_count() == 0:
        print(f'no subscriber on {pub.topic_name} within {timeout} s', file=sys.stderr)
        return 1
    for i in range(count):
        pub.publish(sample_message(kind, i))
    # Stay alive until the echo side has left (it exits after receiving everything).
    while pub.get_subscription_count() > 0 and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
    return 0


def _echo(node, kind: str, count: int, timeout: float, output: str) -> int:
    received: List[dict] = []
    node.create_subscription(TYPES[kind], TOPIC.format(kind),
                             lambda m: received.append(message_to_dict(m)), QOS)
    deadline = time.monotonic() + timeout
    while len(received) < count and time.monotonic() < deadline:
        rclpy.spin_once(node, timeout_sec=0.05)
    with open(output, 'w', encoding='utf-8') as f:
        json.dump(received, f)
    if len(received) < count:
        print(f'received {len(received)} of {count} messages within {timeout} s',
              file=sys.stderr)
        return 1
    return 0


def main(argv: Optional[List[str]] = None) -> int:
    """Entry point of the ``roundtrip_probe`` console script."""
    args_in = rclpy.utilities.remove_ros_args(sys.argv if argv is None else ['probe'] + argv)
    parser = argparse.ArgumentParser(prog='roundtrip_probe', description=__doc__.splitlines()[0])
    parser.add_argument('mode', choices=['publish', 'echo'])
    parser.add_argument('--type', dest='kind', choices=sorted(TYPES), required=True)
    parser.add_argument('--count', type=int, default=5)
    parser.add_argument('--timeout', type=float, default=30.0)
    parser.add_argument('--output', default='probe.json')
    args = parser.parse_args(args_in[1:])
    rclpy.init(args=sys.argv if argv is None else None)
    node = rclpy.create_node(f'roundtrip_probe_{args.mode}')
    try:
        if args.mode == 'publish':
            return _publish(node, args.kind, args.count, args.timeout)
        return _echo(node, args.kind, args.count, args.timeout, args.output)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    sys.exit(main())
