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
Benchmark the whole live image path: N HD cameras -> bringup (pose2d_node x N + fusion_node).

This process plays the cameras: the real 1920x1080 Panoptic frames of
``../shared/data/panoptic_demo`` (camera i of the rig shows its own view), looped, each time
point held ``--hold-s`` seconds, published free-running at ``--rate`` Hz as ``sensor_msgs/Image``
(bgr8, best effort, the stamp = wall clock at publish = capture time). ``bringup`` runs as a
child process with the shipped params files, exactly as a user starts it. Printed per camera
count and execution provider:

- tracks rate (``/fusion_node/tracks`` messages per second) against the publish rate;
- capture -> tracks latency p50 / p95 (stamp -> receipt of the tracks by this process);
- per-stage medians from ``/diagnostics``: transport (capture -> pose2d receipt), wait (behind
  the previous inference), decode, pre, inference, post, publish, fusion (``Fusion.step``);
- drops by stage: lost before pose2d (published - received: DDS / QoS; whole run),
  pose2d newest-only (replaced before inference), fusion synchroniser (dropped by sync);
- the sets fusion_node emitted, how many were partial, and how many incomplete sets were
  decided on a camera's skip notice (``persons_2d/skipped``) instead of waiting out
  ``sync.max_wait_s`` (emitted partial, or dropped with too few views);

  the last two in the measured window (the nodes' counters at its start and end, read from
  diagnostics published once a second) and over the whole run (start-up included);
- people found: skeletons observed in each tracks message (``last_observed`` = the set's
  stamp), per time point: the share of sets with all 3 Panoptic people, and the minimum.

    python bench/bench_pipeline.py [--cameras 1 2 4] [--rate 10] [--seconds 20]
        [--providers auto] [--pose2d-param model.input_size:=384x640 ...]

Nothing here is asserted: the figures go to the README with the load (uptime) of the run.
"""

import argparse
import os
import statistics
import struct
import subprocess
import sys
import tempfile
import threading
import time
from typing import Dict, List

import cv2
import numpy as np
import yaml

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.path.join(os.path.dirname(ROOT), 'shared', 'data', 'panoptic_demo')
RIG = os.path.join(ROOT, 'config', 'rigs', 'panoptic_demo.yaml')
CAMERAS = ('00_03', '00_06', '00_12', '00_13', '00_23')
FRAMES = ('00004500', '00005514', '00006859', '00009348', '00013007')
STAMP = struct.Struct('<iI')     # header.stamp, right after the 4-byte CDR encapsulation
STAGES = ('transport', 'wait', 'decode', 'pre', 'inference', 'post', 'publish')
NS = 1_000_000_000


def _percentile(values: List[float], q: float) -> float:
    return float(np.percentile(values, q)) if values else float('nan')


def _median(values: List[float]) -> float:
    values = [v for v in values if v == v]
    return statistics.median(values) if values else float('nan')


def _load_frames(cameras: List[str]) -> Dict[str, List[np.ndarray]]:
    out = {}
    for i, cam in enumerate(cameras):
        src = CAMERAS[i % len(CAMERAS)]          # more cameras than views: views repeat
        out[cam] = [cv2.imread(os.path.join(DATA, src, f'{src}_{f}.jpg')) for f in FRAMES]
        if any(img is None for img in out[cam]):
            raise SystemExit(f'bench_pipeline: cannot read the frames of {src} in {DATA}')
    return out


def _counts(diags: Dict[str, Dict[str, str]]) -> Dict[str, int]:
    """Sum the nodes' running counters in the latest diagnostics (``diags``: name -> values)."""
    pose = [v for k, v in diags.items() if k.endswith(' inference')]
    pipeline = [v for v in diags.values() if 'sets emitted' in v]

    def fusion(key: str) -> int:
        return int(float(pipeline[0].get(key, 0))) if pipeline else 0

    return {
        'received': sum(int(d.get('Images received', 0)) for d in pose),
        'dropped_pose2d': sum(int(d.get('Dropped before inference (newer image arrived)', 0))
                              for d in pose),
        'dropped_sync': sum(int(d.get('dropped by sync', 0)) for d in diags.values()),
        'sets emitted': fusion('sets emitted'), 'partial sets': fusion('partial sets'),
        'skip decided': fusion('incomplete sets decided on skip notices'),
    }


def run(cameras: List[str], rate: float, seconds: float, hold_s: float, provider: str,
        pose2d_params: List[str], warmup_s: float, verbose: bool,
        fusion_params: List[str] = (), latency_log: str = '') -> dict:
    """Start bringup, play the cameras, collect tracks and diagnostics; return the figures."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray
    from mv3dpose_msgs.msg import Person2DArray, TrackedSkeletonArray
    from mv3dpose_ros.ros.images import numpy_to_image
    from mv3dpose_ros.ros.messages import stamp_to_ns
    from mv3dpose_ros.ros.names import camera_namespace
    from mv3dpose_ros.ros.qos import reliable_qos, sensor_qos
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import Image
    from std_msgs.msg import Header

    frames = _load_frames(cameras)
    wires = {c: [bytearray(serialize_message(numpy_to_image(img, Header(frame_id=c), 'bgr8')))
                 for img in imgs] for c, imgs in frames.items()}
    tmp = tempfile.mkdtemp(prefix='bench_pipeline_')
    log = open(os.path.join(tmp, 'bringup.log'), 'w')
    params = [f'model.providers:={provider}'] + list(pose2d_params)
    if len(cameras) > 1:
        cmd = ['mv3dpose_bringup', '--rig', RIG, '--cameras', *cameras]
        for p in params:
            cmd += ['--pose2d-param', p]
        for p in fusion_params:
            cmd += ['--fusion-param', p]
    else:
        # Fusion needs two cameras: one camera is pose2d_node alone, as bringup would start it.
        from mv3dpose_ros.nodes.bringup import _nest, _parse_assignments, split_threads
        values = {'model.threads': split_threads(1),
                  **_parse_assignments(params, '--pose2d-param')}
        over = os.path.join(tmp, 'pose2d.yaml')
        with open(over, 'w') as f:
            yaml.safe_dump({'/**/pose2d_node': {'ros__parameters': _nest(values)}}, f)
        ns = camera_namespace(cameras[0])
        cmd = ['pose2d_node', '--ros-args', '-r', f'__ns:=/{ns}', '-r',
               f'image:=/{ns}/image_raw', '--params-file',
               os.path.join(ROOT, 'config', 'pose2d.yaml'), '--params-file', over]
    proc = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, cwd=ROOT,
                            start_new_session=True)
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = rclpy.create_node('bench_pipeline_outputs', context=ctx)
    ex = SingleThreadedExecutor(context=ctx)
    shown: Dict[int, int] = {}                  # stamp -> time point index
    latency, observed, arrivals, other = [], [], [], [0]
    diags: Dict[str, Dict[str, str]] = {}

    def on_tracks(msg) -> None:
        now = time.time_ns()
        stamp = stamp_to_ns(msg.header.stamp)
        if stamp not in shown:                   # e.g. an idle step of fusion_node: no set
            other[0] += 1
            return
        latency.append((now - stamp) / 1e6)
        arrivals.append(now)
        if hasattr(msg, 'skeletons'):
            seen = sum(1 for s in msg.skeletons
                       if s.state != s.DELETED and stamp_to_ns(s.last_observed) == stamp)
        else:                                    # one camera: people in the 2D output
            seen = sum(1 for p in msg.persons if p.score >= 0.5)
        observed.append((shown.get(stamp, -1), seen))

    def on_diag(msg) -> None:
        for s in msg.status:
            diags[s.name] = {kv.key: kv.value for kv in s.values}

    if len(cameras) > 1:
        node.create_subscription(TrackedSkeletonArray, '/fusion_node/tracks', on_tracks,
                                 reliable_qos(50))
    else:
        node.create_subscription(Person2DArray, f'/{camera_namespace(cameras[0])}/persons_2d',
                                 on_tracks, reliable_qos(50))
    node.create_subscription(DiagnosticArray, '/diagnostics', on_diag, reliable_qos(50))
    # The receiving side spins in its own thread and context, so that publishing 6 MB images
    # does not delay the receipt of the outputs (latency is also read from the nodes' own
    # diagnostics, measured where the output is published).
    receiver = SingleThreadedExecutor(context=ctx)
    receiver.add_node(node)
    node = rclpy.create_node('bench_pipeline_publisher', context=ctx)
    ex.add_node(node)
    running = threading.Event()
    running.set()

    def spin_receiver() -> None:
        while running.is_set() and ctx.ok():
            receiver.spin_once(timeout_sec=0.05)

    threading.Thread(target=spin_receiver, name='receiver', daemon=True).start()
    pubs = {c: node.create_publisher(Image, f'/{camera_namespace(c)}/image_raw',
                                     sensor_qos('best_effort', 1)) for c in cameras}
    published = 0
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not all(
                p.get_subscription_count() for p in pubs.values()):
            ex.spin_once(timeout_sec=0.05)
            if proc.poll() is not None:
                raise RuntimeError('bringup exited:\n' + open(log.name).read()[-3000:])
        if time.monotonic() >= deadline:
            raise RuntimeError('pose2d nodes did not subscribe within 120 s:\n'
                               + open(log.name).read()[-3000:])
        period = 1.0 / rate
        start = time.monotonic()
        measure_from = None
        counts_at_start: Dict[str, int] = {}
        next_t = start
        k = 0
        while True:
            now = time.monotonic()
            if measure_from is None and latency and now - start >= warmup_s:
                measure_from = now
                latency.clear()
                observed.clear()
                arrivals.clear()
                published_at_start = published
                counts_at_start = _counts(dict(diags))
            if measure_from is not None and now - measure_from >= seconds:
                break
            if now - start > warmup_s + seconds + 60:
                raise RuntimeError('no tracks after the warm-up:\n'
                                   + open(log.name).read()[-3000:])
            point = int(k * period / hold_s) % len(FRAMES)
            stamp = time.time_ns()
            sec, nanosec = divmod(stamp, NS)
            shown[stamp] = point
            for c in cameras:
                data = wires[c][point]
                STAMP.pack_into(data, 4, sec, nanosec)
                pubs[c].publish(bytes(data))
            published += 1
            k += 1
            next_t += period
            while True:                          # free-running: never waits for the pipeline
                left = next_t - time.monotonic()
                if left <= 0:
                    break
                ex.spin_once(timeout_sec=min(left, 0.005))
        window = time.monotonic() - measure_from
        if latency_log:
            with open(latency_log, 'w') as out:
                out.write('# tracks receipt [s since the epoch], capture -> tracks [ms], '
                          'time point, people observed\n')
                for at, ms, (point, seen) in zip(arrivals, latency, observed):
                    out.write(f'{at / 1e9:.3f} {ms:.1f} {point} {seen}\n')
        sets_published = published - published_at_start
        end = time.monotonic() + 1.5             # let the last diagnostics arrive
        while time.monotonic() < end:
            ex.spin_once(timeout_sec=0.05)
    finally:
        running.clear()
        proc.send_signal(2)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:
            proc.kill()
        log.close()
        time.sleep(0.1)
        ex.shutdown()
        receiver.shutdown()
        rclpy.shutdown(context=ctx)
    pose = [v for k, v in diags.items() if k.endswith(' inference')]
    stage = {s: _median([float(d.get(f'Stage {s} median (ms)', 'nan')) for d in pose])
             for s in STAGES}
    fusion = [v for k, v in diags.items() if 'processing median (ms)' in v]
    stage['fusion'] = _median([float(d['processing median (ms)']) for d in fusion])
    if len(cameras) > 1:         # capture stamp -> ~/tracks published, inside fusion_node
        inside = (_median([float(d['latency median (ms)']) for d in fusion]),
                  _median([float(d['latency p95 (ms)']) for d in fusion]))
    else:                        # capture stamp -> persons_2d published, inside pose2d_node
        inside = (_median([float(d.get('Capture to publish median (ms)', 'nan')) for d in pose]),
                  _median([float(d.get('Capture to publish p95 (ms)', 'nan')) for d in pose]))
    whole = _counts(diags)
    window_counts = {k: v - counts_at_start.get(k, 0) for k, v in whole.items()}
    per_point = {}
    for point, seen in observed:
        per_point.setdefault(point, []).append(seen)
    if verbose:
        for name in sorted(diags):
            print(f'    {name}: {diags[name]}')
    return {
        'cameras': len(cameras), 'provider': provider, 'rate': rate, 'other': other[0],
        'published_rate': sets_published / window, 'tracks_rate': len(latency) / window,
        'p50': _percentile(latency, 50), 'p95': _percentile(latency, 95), 'inside': inside,
        'stage': stage, 'published_images': published * len(cameras),
        'whole': whole, 'window': window_counts, 'seconds': window,
        'people': {p: (sum(1 for n in v if n >= 3), len(v), min(v)) for p, v in
                   sorted(per_point.items())},
        'threads': [d.get('Intra-op threads', '?') for d in pose][:1],
        'input': sorted({d.get('Input size (HxW)', '?') + ' ' + d.get('Precision', '')
                         for d in pose}),
    }


def _print(r: dict) -> None:
    st = r['stage']
    people = ', '.join(f'tp{p}: {a}/{n} (min {m})' for p, (a, n, m) in r['people'].items()
                       if p >= 0)
    sets = sum(n for a, n, m in r['people'].values())
    full = sum(a for a, n, m in r['people'].values())
    what = 'tracks' if r['cameras'] > 1 else 'persons_2d (no fusion with one camera)'
    print(f'{r["cameras"]} cam x {r["rate"]:g} Hz, {r["provider"]}, input {",".join(r["input"])}'
          f', threads {",".join(map(str, r["threads"]))}:'
          f' {what} {r["tracks_rate"]:.2f} Hz (published {r["published_rate"]:.2f} Hz), '
          f'latency p50 {r["inside"][0]:.0f} ms p95 {r["inside"][1]:.0f} ms (in the node; '
          f'received here p50 {r["p50"]:.0f} p95 {r["p95"]:.0f})', flush=True)
    print('  stage medians (ms): ' + ', '.join(f'{k} {v:.1f}' for k, v in st.items()),
          flush=True)
    win, whole = r['window'], r['whole']
    lost = r['published_images'] - whole['received']
    print(f'  drops in the {r["seconds"]:.0f} s window (whole run): pose2d newest-only '
          f'{win["dropped_pose2d"]} of {win["received"]} images received '
          f'({whole["dropped_pose2d"]} of {whole["received"]}), fusion sync '
          f'{win["dropped_sync"]} ({whole["dropped_sync"]}); before pose2d (DDS/QoS, whole '
          f'run) {lost} of {r["published_images"]} published; {r["other"]} outputs not '
          'stamped like a published set (idle steps) not counted', flush=True)
    if r['cameras'] > 1:
        print(f'  sets in the window (whole run): {win["sets emitted"]} emitted '
              f'({whole["sets emitted"]}), {win["partial sets"]} partial '
              f'({whole["partial sets"]}), {win["skip decided"]} incomplete sets decided on a '
              f'skip notice ({whole["skip decided"]}; persons_2d/skipped: emitted partial, or '
              'dropped with too few views)', flush=True)
    print(f'  people: {"sets" if r["cameras"] > 1 else "images"} with all 3 observed '
          f'{full}/{sets}; per time point {people}', flush=True)


def main() -> int:
    """Run the configurations and print one block each."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--cameras', type=int, nargs='+', default=[1, 2, 4])
    parser.add_argument('--rate', type=float, default=10.0, help='publish rate per camera [Hz]')
    parser.add_argument('--seconds', type=float, default=20.0, help='measured window [s]')
    parser.add_argument('--warmup', type=float, default=5.0, help='after the first tracks [s]')
    parser.add_argument('--hold-s', type=float, default=2.0,
                        help='seconds each Panoptic time point is shown (5 time points)')
    parser.add_argument('--providers', nargs='+', default=None,
                        help='execution providers to compare (default: every available one)')
    parser.add_argument('--pose2d-param', action='append', default=[], metavar='NAME:=VALUE')
    parser.add_argument('--fusion-param', action='append', default=[], metavar='NAME:=VALUE')
    parser.add_argument('--verbose', action='store_true', help='print every diagnostic status')
    parser.add_argument('--latency-log', metavar='FILE', default='',
                        help='write each measured tracks message (receipt, latency, time point, '
                             'people) to FILE (the last run of several)')
    args = parser.parse_args()
    if not os.path.isdir(DATA):
        print(f'bench_pipeline: skipped: no frames at {DATA}')
        return 0
    from mv3dpose_ros.pose2d.estimator import PROVIDERS, resolve_providers
    short = {v: k for k, v in PROVIDERS.items()}
    providers = args.providers or [short[p] for p in resolve_providers('auto')[0]]
    print(f'bench_pipeline: load {os.getloadavg()}, {os.cpu_count()} cores, pose2d params '
          f'{args.pose2d_param or "(shipped defaults)"}, fusion params '
          f'{args.fusion_param or "(shipped defaults)"}', flush=True)
    for provider in providers:
        for n in args.cameras:
            cams = [CAMERAS[i % len(CAMERAS)] if i < len(CAMERAS) else f'{CAMERAS[i % 5]}'
                    for i in range(n)]
            if len(set(cams)) < n:
                print(f'{n} cameras: the rig has {len(CAMERAS)}; skipped')
                continue
            try:
                _print(run(cams, args.rate, args.seconds, args.hold_s, provider,
                           args.pose2d_param, args.warmup, args.verbose, args.fusion_param,
                           args.latency_log))
            except RuntimeError as exc:
                print(f'{n} cam, {provider}: failed: {exc}', flush=True)
    print(f'bench_pipeline: load at the end {os.getloadavg()}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
