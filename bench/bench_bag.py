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
Throughput of the bag tools: write / read / decode of Person2DArray bags, and the player.

1. ``BagWriter`` and ``BagReader`` (no DDS) on a synthetic scene's detections (4 cameras,
   3 people, coco17), MCAP and sqlite3: messages per second and MB per second.
2. ``mv3dpose bag play --rate 0`` into a subscriber over DDS (separate process): messages per
   second that arrive, all of them (RELIABLE).

Figures, not assertions. Usage: ``python bench/bench_bag.py [--frames N] [--no-dds]``
"""

import argparse
import os
import random
import subprocess
import sys
import tempfile
import time

from mv3dpose_ros.io.bag import BagReader, BagWriter, make_qos
from mv3dpose_ros.ros.messages import ns_to_stamp, numpy_to_person2d_array
from mv3dpose_ros.ros.names import persons_topic
from mv3dpose_ros.sim import make_scene
from rclpy.serialization import serialize_message
from std_msgs.msg import Header


def write_bag(path: str, scene, storage: str) -> int:
    """Write the scene's detections as one Person2DArray per camera and frame."""
    n = 0
    with BagWriter(path, storage=storage) as writer:
        for cam in scene.cameras:
            writer.add_topic(persons_topic(cam), 'mv3dpose_msgs/msg/Person2DArray',
                             [make_qos()])
        for t, stamp in enumerate(scene.stamps):
            ns = int(round((1e9 + stamp) * 1e9))
            for cam, c in scene.cameras.items():
                msg = numpy_to_person2d_array(scene.views[t][cam],
                                              Header(stamp=ns_to_stamp(ns), frame_id=cam),
                                              cam, c.width, c.height, scene.layout)
                writer.write(persons_topic(cam), ns, serialize_message(msg))
                n += 1
    return n


def size_mb(path: str) -> float:
    """Return the size of a bag directory in MB."""
    return sum(os.path.getsize(os.path.join(path, f)) for f in os.listdir(path)) / 1e6


def bench_io(scene, tmp: str) -> str:
    """Time writing, raw reading and decoding for both storages."""
    rows = []
    for storage in ('mcap', 'sqlite3'):
        path = os.path.join(tmp, storage)
        t0 = time.perf_counter()
        n = write_bag(path, scene, storage)
        t_write = time.perf_counter() - t0
        with BagReader(path) as reader:
            t0 = time.perf_counter()
            raw = sum(1 for _ in reader.messages())
            t_read = time.perf_counter() - t0
            t0 = time.perf_counter()
            dec = sum(1 for _ in reader.decoded())
            t_dec = time.perf_counter() - t0
        assert raw == dec == n
        mb = size_mb(path)
        rows.append(f'{storage:<8} {n:>6} msgs {mb:6.2f} MB   write {n / t_write:8.0f} msg/s   '
                    f'read {n / t_read:8.0f} msg/s   read+decode {n / t_dec:7.0f} msg/s')
    return '\n'.join(rows)


def bench_play(scene, tmp: str) -> str:
    """Play the MCAP bag as fast as possible into a subscriber in this process."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
    from mv3dpose_msgs.msg import Person2DArray
    os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(100, 199)))
    path = os.path.join(tmp, 'mcap')
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node('bench_bag_listener', context=ctx)
    qos = QoSProfile(depth=1000, history=HistoryPolicy.KEEP_LAST,
                     reliability=ReliabilityPolicy.RELIABLE)
    times = []
    for cam in scene.cameras:
        node.create_subscription(Person2DArray, persons_topic(cam),
                                 lambda m: times.append(time.perf_counter()), qos)
    executor = SingleThreadedExecutor(context=ctx)
    executor.add_node(node)
    total = len(scene.cameras) * len(scene.stamps)
    proc = subprocess.Popen([sys.executable, '-m', 'mv3dpose_ros.cli', 'bag', 'play', path,
                             '--rate', '0', '--wait-for-subscribers', '30', '-q'])
    deadline = time.monotonic() + 120
    while len(times) < total and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    proc.wait(timeout=60)
    node.destroy_node()
    rclpy.shutdown(context=ctx)
    span = times[-1] - times[0] if len(times) > 1 else float('nan')
    return (f'play --rate 0 -> subscriber: {len(times)}/{total} messages received, '
            f'{len(times) / span:.0f} msg/s')


def main() -> None:
    """Print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--frames', type=int, default=500)
    parser.add_argument('--no-dds', action='store_true')
    args = parser.parse_args()
    scene = make_scene(num_cameras=4, num_people=3, num_frames=args.frames, seed=0)
    with tempfile.TemporaryDirectory() as tmp:
        print(f'Person2DArray bags: {args.frames} frames x 4 cameras, 3 people, coco17')
        print(bench_io(scene, tmp))
        if not args.no_dds:
            print(bench_play(scene, tmp))


if __name__ == '__main__':
    main()
