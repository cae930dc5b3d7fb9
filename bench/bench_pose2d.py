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
Per-image cost of pose2d_node's whole path against onnxruntime's bare ``run``.

Whole path = what the node pays per image from the serialised ``sensor_msgs/Image`` its raw
subscription receives: CDR parse (pixels read in place), Image -> numpy, letterbox
pre-processing, inference, post-processing (NMS, inversion), ``Person2DArray`` build and
publish to a matched subscriber. Bare = ``session.run``
on the same pre-processed tensor. The two are interleaved image by image so both see the same
machine load; medians and the overhead (path - bare) / bare are printed. Target: <= 10 %.

    python bench/bench_pose2d.py [--model yolo11n-pose] [--size 640] [--threads 2] [--iters 30]
"""

import argparse
import os
import statistics
import sys
import time

import cv2

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.path.join(os.path.dirname(ROOT), 'shared', 'data', 'panoptic_demo', '00_03')


def main() -> int:
    """Run the benchmark and print the figures; exit 0 with a note when something is absent."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--model', default='yolo11n-pose')
    parser.add_argument('--size', default=None, help='N or HxW (default: the model default)')
    parser.add_argument('--threads', type=int, default=2)
    parser.add_argument('--iters', type=int, default=30)
    args = parser.parse_args()

    from mv3dpose_ros.pose2d.models import ModelNotFound, resolve_model_path
    try:
        path = resolve_model_path(args.model, args.size)
    except ModelNotFound as exc:
        print(f'bench_pose2d: skipped: {exc}')
        return 0
    if not os.path.isdir(DATA):
        print(f'bench_pose2d: skipped: no images at {DATA}')
        return 0
    import rclpy
    from rclpy.parameter import Parameter
    from rclpy.serialization import serialize_message
    from mv3dpose_msgs.msg import Person2DArray
    from mv3dpose_ros.nodes.pose2d_node import Pose2DNode
    from mv3dpose_ros.ros.images import numpy_to_image
    from mv3dpose_ros.ros.messages import ns_to_stamp
    from mv3dpose_ros.ros.qos import reliable_qos
    from std_msgs.msg import Header

    images = [cv2.imread(os.path.join(DATA, f)) for f in sorted(os.listdir(DATA))]
    wires = [serialize_message(numpy_to_image(
        img, Header(stamp=ns_to_stamp((1000 + i) * 10**9), frame_id='cam'), 'bgr8'))
        for i, img in enumerate(images)]

    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = Pose2DNode(context=ctx, namespace='/bench', parameter_overrides=[
        Parameter('model.path', value=path), Parameter('model.threads', value=args.threads)])
    if not node.active:
        print(f'bench_pose2d: node did not start: {node.error}', file=sys.stderr)
        return 1
    sink = rclpy.create_node('bench_sink', context=ctx)
    sink.create_subscription(Person2DArray, '/bench/persons_2d', lambda m: None, reliable_qos())
    time.sleep(0.5)                                   # let the subscription match
    est = node.estimator
    path_ms, bare_ms, stage = [], [], {'deserialise+numpy': [], 'pre': [], 'post+msg': []}
    try:
        for i in range(args.iters + 3):
            wire = wires[i % len(wires)]
            t0 = time.perf_counter()
            out = node.process(wire)
            t1 = time.perf_counter()
            tensor, _ = est.preprocess(images[i % len(images)])
            t2 = time.perf_counter()
            est.run(tensor)
            t3 = time.perf_counter()
            if i < 3:                                  # warm-up
                continue
            assert out is not None
            path_ms.append((t1 - t0) * 1e3)
            bare_ms.append((t3 - t2) * 1e3)
            timing = est.last_timing
            stage['pre'].append(timing.pre_ms)
            stage['post+msg'].append(path_ms[-1] - timing.total_ms + timing.post_ms)
    finally:
        node.destroy_node()
        sink.destroy_node()
        rclpy.shutdown(context=ctx)
    med_path, med_bare = statistics.median(path_ms), statistics.median(bare_ms)
    paired = statistics.median((p - b) / b for p, b in zip(path_ms, bare_ms))
    print(f'bench_pose2d: {os.path.basename(path)} ({est.family} {est.input_size[0]}x'
          f'{est.input_size[1]}), {args.threads} intra-op threads, {len(path_ms)} images '
          f'1920x1080 bgr8')
    print(f'  onnxruntime bare run   median {med_bare:7.2f} ms')
    print(f'  node whole path        median {med_path:7.2f} ms  ({1000 / med_path:.1f} images/s)')
    print(f'    pre-processing       median {statistics.median(stage["pre"]):7.2f} ms')
    print(f'    everything but pre+inference (CDR parse, numpy, post, message, publish) '
          f'median {statistics.median(stage["post+msg"]):.2f} ms')
    added = statistics.median(p - b for p, b in zip(path_ms, bare_ms))
    print(f'  overhead path - bare   median {added:7.2f} ms (what the node adds per image)')
    print(f'  overhead (path - bare) / bare: {100 * (med_path - med_bare) / med_bare:.1f} % of '
          f'medians, {100 * paired:.1f} % median paired (target <= 10 %)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
