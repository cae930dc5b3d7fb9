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
Benchmark the live web view: scene building per tracks message, and DDS -> WebSocket latency.

1. ``skeleton_update`` + protobuf encoding of one ``~/tracks`` message (simulated people,
   COCO-17, all joints valid): median microseconds per message.
2. ``mv3dpose_foxglove_view`` as its own process: the bench publishes ``TrackedSkeletonArray``
   at 30 Hz with the publish wall time as header stamp; a Foxglove WebSocket client subscribed
   to ``/mv3dpose/scene`` and ``/fusion_node/tracks`` takes (receive wall time - stamp):
   median and p95 milliseconds, and how many messages arrived.

Usage: ``python bench/bench_foxglove_view.py [--people 6] [--seconds 6]``
"""

import argparse
import asyncio
import os
import socket
import subprocess
import sys
import threading
import time

from mv3dpose_msgs.msg import TrackedSkeletonArray
from mv3dpose_ros.core.skeleton import get_layout
from mv3dpose_ros.core.types import JointState, Track, TrackState
from mv3dpose_ros.io.foxglove_ws import FoxgloveClient
from mv3dpose_ros.ros.messages import ns_to_stamp, tracks_to_msg
from mv3dpose_ros.ros.qos import reliable_qos
from mv3dpose_ros.viz.scene import skeleton_update
import numpy as np
import rclpy
from std_msgs.msg import Header

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LAYOUT = get_layout('coco17')


def _tracks(people: int, rng: np.random.Generator):
    out = []
    for i in range(people):
        J = LAYOUT.num_joints
        joints = rng.normal([i * 0.8, 0.0, 1.0], [0.2, 0.2, 0.5], size=(J, 3))
        states = np.full(J, JointState.TRIANGULATED, np.uint8)
        out.append(Track(track_id=i + 1, state=TrackState.CONFIRMED, joints=joints,
                         confidence=np.ones(J), joint_state=states,
                         num_views=np.full(J, 4, np.uint8), reprojection_error=np.zeros(J),
                         position=joints[11:13].mean(0), velocity=np.zeros(3),
                         first_seen=0.0, last_observed=0.0))
    return out


def bench_build(people: int, repeat: int = 2000) -> float:
    tracks = _tracks(people, np.random.default_rng(0))
    times = []
    for k in range(repeat):
        t0 = time.perf_counter()
        skeleton_update(tracks, LAYOUT.bones, 'world', k * 33_000_000).encode()
        times.append(time.perf_counter() - t0)
    return float(np.median(times) * 1e6)


def bench_latency(people: int, seconds: float):
    with socket.socket() as s:
        s.bind(('127.0.0.1', 0))
        port = s.getsockname()[1]
    proc = subprocess.Popen(['mv3dpose_foxglove_view', '--port', str(port)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT)
    rclpy.init()
    node = rclpy.create_node('bench_foxglove_feeder')
    pub = node.create_publisher(TrackedSkeletonArray, '/fusion_node/tracks', reliable_qos(10))
    tracks = _tracks(people, np.random.default_rng(1))
    stop = threading.Event()

    def feed():
        while not stop.is_set():
            header = Header(stamp=ns_to_stamp(time.time_ns()), frame_id='world')
            pub.publish(tracks_to_msg(tracks, header, 'coco17'))
            time.sleep(1 / 30)

    async def client():
        deadline = time.monotonic() + 30
        while True:
            try:
                async with FoxgloveClient(f'ws://127.0.0.1:{port}') as c:
                    await c.wait_for_topics(['/mv3dpose/scene', '/fusion_node/tracks'], 10)
                    await c.subscribe(['/mv3dpose/scene', '/fusion_node/tracks'])
                    out = {'/mv3dpose/scene': [], '/fusion_node/tracks': []}
                    end = time.monotonic() + seconds
                    while time.monotonic() < end:
                        for m in await c.receive(0.2):
                            out[m.topic].append((m.received_ns - m.log_time) / 1e6)
                    return out
            except OSError:
                if time.monotonic() > deadline:
                    raise
                await asyncio.sleep(0.5)

    thread = threading.Thread(target=feed, daemon=True)
    try:
        while pub.get_subscription_count() == 0 and proc.poll() is None:
            time.sleep(0.1)
        thread.start()
        return asyncio.run(client())
    finally:
        stop.set()
        thread.join(2)
        node.destroy_node()
        rclpy.shutdown()
        proc.terminate()
        proc.wait(10)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--people', type=int, default=6)
    parser.add_argument('--seconds', type=float, default=6.0)
    args = parser.parse_args()
    for people in sorted({1, 3, args.people}):
        print(f'scene build + encode, {people} people x 17 joints: '
              f'median {bench_build(people):.0f} us per tracks message')
    got = bench_latency(args.people, args.seconds)
    for topic, lat in got.items():
        if not lat:
            print(f'{topic}: nothing received')
            continue
        print(f'{topic}: {len(lat)} messages in {args.seconds:.0f} s at 30 Hz, {args.people} '
              f'people; publish -> WebSocket client latency median '
              f'{np.median(lat):.1f} ms, p95 {np.percentile(lat, 95):.1f} ms')
    return 0


if __name__ == '__main__':
    sys.exit(main())
