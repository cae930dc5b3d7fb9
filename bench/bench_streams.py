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
How many HD camera streams one machine's 2D stage serves, per execution provider.

N processes, one pose estimator each (as ``bringup`` starts one pose2d_node per camera, each
with ``cores // N`` intra-op threads), each fed its own camera's real 1920x1080 Panoptic frames
free-running at ``--rate`` Hz from its own phase. Newest image only, as in pose2d_node: an image
that comes due while the model is busy replaces the one waiting, and counts as dropped. Printed
per (provider, N): images/s inferred per stream, drops, and the latency from an image's capture
instant to its detections (the whole 2D path: letterbox, inference, decoding; no ROS transport,
which ``bench_image_transport.py`` measures). ``--rate 0`` feeds as fast as the model takes
images: the most each stream gets.

    python bench/bench_streams.py [--providers cpu] [--streams 1 2 4] [--rate 10]
        [--seconds 8] [--size 384x640]

Runs without ROS (numpy, OpenCV, onnxruntime), so it also runs on a GPU machine that has no
ROS installed: ``--providers cuda cpu --streams 1 4 8``.
"""

import argparse
import multiprocessing
import os
import queue
import statistics
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEMO = os.path.join(os.path.dirname(ROOT), 'shared', 'data', 'panoptic_demo')
CAMERAS = ('00_03', '00_06', '00_12', '00_13', '00_23')


def _frames(camera: str) -> list:
    """Return the decoded real frames of one Panoptic camera (BGR, 1920x1080)."""
    import cv2
    folder = os.path.join(DEMO, camera)
    return [cv2.imread(os.path.join(folder, f)) for f in sorted(os.listdir(folder))
            if f.endswith('.jpg')]


def _stream(index: int, path: str, provider: str, threads: int, rate: float, seconds: float,
            start, results) -> None:
    """Load, report ready, run one camera stream from ``start`` on; put its figures on results."""
    sys.path.insert(0, ROOT)
    from mv3dpose_ros.pose2d.estimator import open_estimator
    est = open_estimator(path, threads=threads, providers=provider)
    frames = _frames(CAMERAS[index % len(CAMERAS)])
    for image in frames[:3]:                          # warm-up (CUDA: kernels, workspace)
        est.infer(image)
    results.put(('ready', index))
    waited = time.time() + 120.0
    while start.value == 0.0:                         # until every stream has loaded its model
        if time.time() > waited:                      # the parent gave up (or died)
            return
        time.sleep(0.005)
    period = 1.0 / rate if rate > 0 else 0.0
    phase = start.value + period * index / 7.0        # free-running: each camera its own phase
    latency, stages, done, dropped, last = [], [], 0, 0, -1
    while time.time() < start.value:
        time.sleep(0.001)
    end = start.value + seconds
    while True:
        now = time.time()
        if now >= end:
            break
        if period:
            due = int((now - phase) // period)        # the newest image captured by now
            if due <= last:
                time.sleep(max(0.0, phase + (last + 1) * period - now))
                continue
            dropped += max(0, due - last - 1)
            captured = phase + due * period
            last = due
        else:
            captured = now
        est.infer(frames[done % len(frames)])
        latency.append((time.time() - captured) * 1e3)
        t = est.last_timing
        stages.append((t.pre_ms, t.infer_ms, t.post_ms))
        done += 1
    results.put({'index': index, 'provider': est.provider, 'warnings': est.warnings,
                 'latency': latency, 'stages': stages, 'done': done, 'dropped': dropped})


def run_streams(path: str, provider: str, count: int, rate: float, seconds: float) -> dict:
    """Run ``count`` streams at once in their own processes and return their pooled figures."""
    ctx = multiprocessing.get_context('spawn')        # no CUDA state across fork
    results = ctx.Queue()
    threads = max(1, (os.cpu_count() or 1) // count)
    start = ctx.Value('d', 0.0)
    procs = [ctx.Process(target=_stream, args=(i, path, provider, threads, rate, seconds,
                                               start, results)) for i in range(count)]
    for p in procs:
        p.start()
    out, ready = [], 0
    deadline = time.time() + 120.0 + seconds
    while len(out) < count and time.time() < deadline:
        try:
            item = results.get(timeout=1.0)
        except queue.Empty:
            if not any(p.is_alive() for p in procs):
                break
            continue
        if isinstance(item, tuple):
            ready += 1
            if ready == count:
                start.value = time.time() + 0.5
        else:
            out.append(item)
    for p in procs:
        p.join(timeout=5.0)
        if p.is_alive():
            p.kill()
    if len(out) < count:
        return {'error': f'{count - len(out)} of {count} streams gave no result'}
    latency = [v for r in out for v in r['latency']]
    stages = [s for r in out for s in r['stages']]
    done = sum(r['done'] for r in out)
    offered = done + sum(r['dropped'] for r in out)
    latency.sort()
    return {'provider': out[0]['provider'], 'warnings': out[0]['warnings'], 'threads': threads,
            'rate_each': done / count / seconds, 'images_s': done / seconds,
            'dropped_pct': 100.0 * (offered - done) / offered if offered else 0.0,
            'p50': latency[len(latency) // 2] if latency else float('nan'),
            'p95': latency[int(0.95 * (len(latency) - 1))] if latency else float('nan'),
            'pre': statistics.median(s[0] for s in stages),
            'infer': statistics.median(s[1] for s in stages),
            'post': statistics.median(s[2] for s in stages)}


def main() -> int:
    """Print the figures per (provider, stream count); exit 0 with a note if data is absent."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--model', default='yolo11n-pose')
    parser.add_argument('--size', default='384x640', help='HxW of the fetched model (16:9: '
                        '384x640, what model.input_size auto picks for 1920x1080)')
    parser.add_argument('--providers', nargs='+', default=['cpu'],
                        help='auto, cuda, tensorrt, openvino or cpu; each run separately')
    parser.add_argument('--streams', nargs='+', type=int, default=[1, 2, 4])
    parser.add_argument('--rate', type=float, default=10.0, help='Hz per camera; 0 = flat out')
    parser.add_argument('--seconds', type=float, default=8.0)
    args = parser.parse_args()
    sys.path.insert(0, ROOT)
    import onnxruntime as ort
    from mv3dpose_ros.pose2d.models import ModelNotFound, resolve_model_path
    try:
        path = resolve_model_path(args.model, args.size)
    except ModelNotFound as exc:
        print(f'bench_streams: skipped: {exc}')
        return 0
    if not os.path.isdir(DEMO):
        print(f'bench_streams: skipped: no images at {DEMO}')
        return 0
    rate = f'{args.rate:g} Hz each' if args.rate > 0 else 'flat out'
    print(f'bench_streams: {os.path.basename(path)}, real 1920x1080 frames, {rate}, '
          f'{args.seconds:g} s per run; onnxruntime {ort.__version__} '
          f'({", ".join(ort.get_available_providers())}); {os.cpu_count()} cores')
    print(f'  {"provider":>8} {"N":>2} {"threads":>7} {"Hz each":>8} {"images/s":>8} '
          f'{"dropped":>7} {"p50 ms":>7} {"p95 ms":>7}   stage medians ms (pre/infer/post)')
    for provider in args.providers:
        for count in args.streams:
            r = run_streams(path, provider, count, args.rate, args.seconds)
            if 'error' in r:
                print(f'  {provider:>8} {count:>2}  failed: {r["error"]}')
                continue
            ran = r['provider'].replace('ExecutionProvider', '')
            print(f'  {ran:>8} {count:>2} {r["threads"]:>7} {r["rate_each"]:8.2f} '
                  f'{r["images_s"]:8.1f} {r["dropped_pct"]:6.1f}% {r["p50"]:7.1f} '
                  f'{r["p95"]:7.1f}   {r["pre"]:.1f} / {r["infer"]:.1f} / {r["post"]:.1f}')
            for warning in r['warnings']:
                print(f'           ({provider} asked) {warning}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
