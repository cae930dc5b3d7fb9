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
How many raw 1080p ``sensor_msgs/Image`` arrive between two processes on this host.

A publisher process sends ``--count`` real Panoptic frames (1920x1080 bgr8, 6.2 MB) at
``--rate`` Hz with the sensor-data QoS (best effort, depth 5) that camera drivers use; a
subscriber process (raw subscription, as pose2d_node) counts what arrives. Run once with Fast
DDS's built-in transports and once with ``config/fastdds_shm.xml`` (what env.sh and
mv3dpose_bringup apply), and print both. Each side also reports its CPU time per image.
Both run with the malloc setting the image nodes use (transparent huge pages for image-sized
buffers, ``mv3dpose_ros/ros/system/memory.py``). ``--buffers`` repeats the shared-memory pair with
glibc's defaults (a fresh 4 KiB-page ``mmap`` per 6 MB buffer) and with 6 MB buffers kept in
the heap (``MALLOC_MMAP_THRESHOLD_``, ``MALLOC_TRIM_THRESHOLD_``; see docs/rig.md, "HD images
and the CPU", for why the nodes do not do that), to show what the page faults cost:

    python bench/bench_image_transport.py [--count 50] [--rate 10] [--reliable] [--buffers]
"""

import argparse
import os
import subprocess
import sys
import time
from typing import Tuple

from mv3dpose_ros.ros.system.memory import OPT_OUT, thp_mode, with_hugepages

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FRAME = os.path.join(os.path.dirname(ROOT), 'shared', 'data', 'panoptic_demo', '00_03',
                     '00_03_00004500.jpg')
PROFILE = os.path.join(ROOT, 'config', 'fastdds_shm.xml')
TOPIC = '/bench_images/image_raw'


def _qos(reliable: bool):
    from mv3dpose_ros.ros.qos import sensor_qos
    return sensor_qos('reliable' if reliable else 'best_effort', 5)


def subscriber(args: argparse.Namespace) -> int:
    """Count the images that arrive until none came for 3 s after the first (or 60 s)."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import Image
    rclpy.init()
    node = rclpy.create_node('bench_image_sub')
    got = []
    cpu = []

    def on_image(data: bytes) -> None:
        got.append(len(data))
        cpu.append(time.process_time())

    node.create_subscription(Image, TOPIC, on_image, _qos(args.reliable), raw=True)
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    print('ready', flush=True)
    start = last = time.monotonic()
    while time.monotonic() - start < 120:
        n = len(got)
        ex.spin_once(timeout_sec=0.05)
        if len(got) != n:
            last = time.monotonic()
        if os.path.exists(args.done_file) and time.monotonic() - last > 3.0:
            break
    per_image = (cpu[-1] - cpu[0]) / (len(cpu) - 1) * 1e3 if len(cpu) > 1 else float('nan')
    print(f'received {len(got)} cpu_ms {per_image:.2f}', flush=True)
    node.destroy_node()
    rclpy.shutdown()
    return 0


def publisher(args: argparse.Namespace) -> int:
    """Publish ``count`` frames at ``rate`` Hz once the subscriber matched."""
    import cv2
    from mv3dpose_ros.ros.images import numpy_to_image
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import Image
    rclpy.init()
    node = rclpy.create_node('bench_image_pub')
    pub = node.create_publisher(Image, TOPIC, _qos(args.reliable))
    msg = numpy_to_image(cv2.imread(FRAME))
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    # the package's one wait for subscribers (it settles for the other side's discovery)
    from mv3dpose_ros.ros.subscribers import SubscriberWait
    SubscriberWait({TOPIC: 'sensor_msgs/msg/Image'}, lambda _t: pub.get_subscription_count(),
                   prefix='publisher: ').wait(ex, 30.0)
    period = 1.0 / args.rate
    t0 = time.monotonic()
    c0 = time.process_time()
    for k in range(args.count):
        msg.header.stamp = node.get_clock().now().to_msg()
        pub.publish(msg)
        ex.spin_once(timeout_sec=max(0.0, t0 + (k + 1) * period - time.monotonic()))
        while time.monotonic() < t0 + (k + 1) * period:
            time.sleep(0.001)
    per_image = (time.process_time() - c0) / args.count * 1e3
    print(f'sent {args.count} cpu_ms {per_image:.2f}', flush=True)
    open(args.done_file, 'w').close()
    time.sleep(1.0)
    node.destroy_node()
    rclpy.shutdown()
    return 0


def run_pair(args: argparse.Namespace, profile: str,
             malloc: str = 'hugepages') -> Tuple[int, float, float]:
    """
    Run a subscriber and a publisher process; return (arrived, sub, pub CPU ms/image).

    ``malloc``: ``hugepages`` as the nodes run (ros/system/memory.py), ``glibc`` glibc's defaults,
    ``heap`` 6 MB buffers kept in the heap (the variant the nodes do not use).
    """
    env = dict(os.environ)
    env.pop('FASTRTPS_DEFAULT_PROFILES_FILE', None)
    env.pop('FASTDDS_DEFAULT_PROFILES_FILE', None)
    env.pop('GLIBC_TUNABLES', None)
    env.pop(OPT_OUT, None)
    if profile:
        env['FASTRTPS_DEFAULT_PROFILES_FILE'] = profile
    if malloc == 'hugepages':
        env = with_hugepages(env)
    elif malloc == 'heap':
        env.update(MALLOC_MMAP_THRESHOLD_=str(32 << 20), MALLOC_TRIM_THRESHOLD_=str(256 << 20))
    done = os.path.join('/tmp', f'bench_images_{os.getpid()}_{bool(profile)}.done')
    if os.path.exists(done):
        os.unlink(done)
    common = [sys.executable, __file__, '--count', str(args.count), '--rate', str(args.rate),
              '--done-file', done] + (['--reliable'] if args.reliable else [])
    sub = subprocess.Popen(common + ['--role', 'sub'], env=env, stdout=subprocess.PIPE,
                           text=True)
    sub.stdout.readline()
    pub = subprocess.run(common + ['--role', 'pub'], env=env, capture_output=True, text=True,
                         timeout=300)
    out, _ = sub.communicate(timeout=180)
    if os.path.exists(done):
        os.unlink(done)
    if pub.returncode != 0:
        raise SystemExit(f'publisher failed: {pub.stderr[-2000:]}')
    got = out.split('received')[-1].split()
    sent = pub.stdout.split('sent')[-1].split()
    return int(got[0]), float(got[2]), float(sent[2])


def main() -> int:
    """Measure both transports and print the counts."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--count', type=int, default=50)
    parser.add_argument('--rate', type=float, default=10.0)
    parser.add_argument('--reliable', action='store_true', help='RELIABLE instead of best effort')
    parser.add_argument('--buffers', action='store_true',
                        help='also run the shared-memory pair with glibc malloc defaults and '
                             'with 6 MB buffers kept in the heap')
    parser.add_argument('--role', choices=('sub', 'pub'), help=argparse.SUPPRESS)
    parser.add_argument('--done-file', help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.role == 'sub':
        return subscriber(args)
    if args.role == 'pub':
        return publisher(args)
    if not os.path.isfile(FRAME):
        print(f'bench_image_transport: skipped: no frame at {FRAME}')
        return 0
    qos = 'reliable' if args.reliable else 'best effort'
    print(f'1920x1080 bgr8 ({1920 * 1080 * 3 / 1e6:.1f} MB), {args.count} images at '
          f'{args.rate:g} Hz, {qos}, depth 5, two processes, '
          f'ROS_AUTOMATIC_DISCOVERY_RANGE={os.environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE")}')
    runs = [('Fast DDS built-in transports', '', 'hugepages'),
            ('config/fastdds_shm.xml', PROFILE, 'hugepages')]
    if args.buffers:
        runs += [('shm, glibc malloc defaults', PROFILE, 'glibc'),
                 ('shm, buffers kept in the heap', PROFILE, 'heap')]
    print(f'transparent huge pages: {thp_mode()}; "hugepages" (the nodes\' setting) is '
          f'{"in effect" if with_hugepages({}).get("GLIBC_TUNABLES") else "a no-op"} here')
    for label, profile, malloc in runs:
        got, sub_ms, pub_ms = run_pair(args, profile, malloc)
        print(f'{label:32s}: {got}/{args.count} arrived ({100.0 * got / args.count:.0f} %); CPU '
              f'per image: subscriber {sub_ms:.1f} ms, publisher {pub_ms:.1f} ms')
    return 0


if __name__ == '__main__':
    sys.exit(main())
