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

``--compare`` instead measures each fetched variant of the model (sizes, fp32 / int8) on the
25 real Panoptic views (5 cameras x 5 time points): onnxruntime time per image (median wall
and CPU, interleaved so all variants see the same load) and the people found, i.e. the 3D
people the fusion core triangulates from the 5 views at each time point (the scene has 3) and
from the first 4 (the rig the pipeline benches play), plus the median keypoint shift (2D, and
of the triangulated joints in 3D) against the first variant:

    python bench/bench_pose2d.py --compare [--threads 1] [--providers cpu cuda]

With several ``--providers`` each variant runs on each, and the keypoint shift is taken against
the same variant on the first provider (``cpu cuda``: does the GPU find what the CPU finds?).
"""

import argparse
import os
import resource
import statistics
import sys
import time
from typing import Sequence

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
    parser.add_argument('--compare', action='store_true',
                        help='speed and people found of every fetched variant (see above)')
    parser.add_argument('--providers', nargs='+', default=['auto'],
                        help='--compare: execution providers (auto, cuda, cpu, ...), each run')
    args = parser.parse_args()
    if args.compare:
        return compare(args.model, args.threads, args.providers)

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
    from mv3dpose_ros.nodes.pose2d.node import Pose2DNode
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


def _cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _shift_px(ref, det) -> float:
    """Return the median distance of confident keypoints of nearest-centre matched people."""
    import numpy as np
    out = []
    for a in ref:
        if len(det) == 0:
            break
        ca = a[a[:, 2] > 0.5, :2].mean(0) if (a[:, 2] > 0.5).any() else a[:, :2].mean(0)
        b = min(det, key=lambda d: np.linalg.norm(d[:, :2].mean(0) - ca))
        both = (a[:, 2] > 0.5) & (b[:, 2] > 0.5)
        out += list(np.linalg.norm(a[both, :2] - b[both, :2], axis=1))
    return out


def _shift_3d_mm(ref, other) -> list:
    """Return 3D joint distances [mm] between each reference person and its nearest match."""
    import numpy as np
    out = []
    for a in ref:
        if not len(other):
            continue
        ok_a = np.isfinite(a[:, :3]).all(1)
        b = min(other, key=lambda d: np.nanmean(np.linalg.norm(d[:, :3] - a[:, :3], axis=1)))
        both = ok_a & np.isfinite(b[:, :3]).all(1)
        out += list(1e3 * np.linalg.norm(a[both, :3] - b[both, :3], axis=1))
    return out


def compare(model: str, threads: int, providers: Sequence[str] = ('auto',)) -> int:
    """Print speed and people found of each fetched variant of ``model`` on each provider."""
    import numpy as np
    from mv3dpose_ros.core.geometry.calibration import load_calibration
    from mv3dpose_ros.core.fusion.pipeline import Fusion
    from mv3dpose_ros.pose2d.estimator import open_estimator
    from mv3dpose_ros.pose2d.models import get_spec, list_fetched, model_file, PRECISIONS, size_tag
    demo = os.path.dirname(DATA)
    cams = ('00_03', '00_06', '00_12', '00_13', '00_23')
    frames = ('00004500', '00005514', '00006859', '00009348', '00013007')
    spec = get_spec(model)
    # The registry's sizes first (640x640 fp32 is the reference), then every other fetched size
    # of the model, largest input first.
    extra = sorted({tuple(meta['input_size']) for _, meta in list_fetched()
                    if meta.get('name') == model and meta.get('input_size')}
                   - set(spec.sizes), key=lambda s: -s[0] * s[1])
    variants = [(s, p, e) for p in PRECISIONS for s in list(spec.sizes) + extra
                for e in providers if os.path.isfile(model_file(model, s, None, p))]
    if not variants or not os.path.isdir(demo):
        print(f'bench_pose2d --compare: skipped: no fetched {model} or no {demo}')
        return 0
    calib = load_calibration(os.path.join(demo, 'camera_parameters.json'), cameras=cams)
    # The first 4 cameras: the rig bench_pipeline.py plays (in-process and --publishers).
    calib4 = load_calibration(os.path.join(demo, 'camera_parameters.json'), cameras=cams[:4])
    images = {(c, f): cv2.imread(os.path.join(demo, c, f'{c}_{f}.jpg')) for c in cams
              for f in frames}
    ests = [open_estimator(model_file(model, s, None, p), threads=threads, providers=e)
            for s, p, e in variants]
    # The reference of each variant: variant 0, or with several providers the same model on
    # the first provider.
    ref = [0 if len(providers) == 1 else variants.index((s, p, providers[0]))
           for s, p, _ in variants]
    wall = [[] for _ in ests]
    cpu = [[] for _ in ests]
    dets = [{} for _ in ests]
    poses3d = [{} for _ in ests]
    for rep in range(2):
        for key, image in images.items():
            for i, est in enumerate(ests):
                tensor, _ = est.preprocess(image)
                c0, w0 = _cpu_s(), time.perf_counter()
                est.run(tensor)
                w1, c1 = time.perf_counter(), _cpu_s()
                wall[i].append((w1 - w0) * 1e3)
                cpu[i].append((c1 - c0) * 1e3)
                if rep == 0:
                    dets[i][key] = est.infer(image).keypoints
    print(f'bench_pose2d --compare: {model} on {len(images)} real 1920x1080 Panoptic views, '
          f'{threads} intra-op thread(s), load {os.getloadavg()}')
    for est in ests:
        for warning in est.warnings:
            print(f'  ({os.path.basename(est.path)}) {warning}')
    for i, (size, precision, _) in enumerate(variants):
        people, people4 = [], []
        for f in frames:
            fusion = Fusion(calib, 'coco17')
            fusion.step({c: dets[i][c, f] for c in cams}, 0.0)
            people.append(int(fusion.last_poses.shape[0]))
            poses3d[i][f] = fusion.last_poses
            fusion = Fusion(calib4, 'coco17')
            fusion.step({c: dets[i][c, f] for c in cams[:4]}, 0.0)
            people4.append(int(fusion.last_poses.shape[0]))
        r = ref[i]
        shift3d = [d for f in frames for d in _shift_3d_mm(poses3d[r][f], poses3d[i][f])]
        shift = [d for key in images for d in _shift_px(dets[r][key], dets[i][key])]
        where = ests[i].provider.replace('ExecutionProvider', '')
        print(f'  {size_tag(size):>8} {precision} {where}: run median '
              f'{statistics.median(wall[i]):6.1f} '
              f'ms wall, {statistics.median(cpu[i]):6.1f} ms CPU; 3D people per time point '
              f'{people} (scene: 3), with 4 cameras {people4}; keypoint shift vs '
              f'{size_tag(variants[r][0])} {variants[r][1]} '
              f'{ests[r].provider.replace("ExecutionProvider", "")}: median '
              f'{np.median(shift) if shift else float("nan"):.2f} px, '
              f'3D {np.median(shift3d) if shift3d else float("nan"):.0f} mm')
    return 0


if __name__ == '__main__':
    sys.exit(main())
