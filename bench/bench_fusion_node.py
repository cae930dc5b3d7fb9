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
Benchmark the running fusion_node: latency from capture stamp to output, and its CPU share.

For each configuration (default 5 cameras x 4 people and 16 x 6, 30 Hz) a synthetic scene is
published by this process as per-camera ``Person2DArray`` streams, stamped with the wall
clock at publication (so pose2d latency is excluded: this is the fusion node's own share),
into ``fusion_node`` started as a separate process with the shipped params file. The
messages are serialised beforehand and only their stamp is patched at send time, so the
feeder adds ~0.05 ms per message instead of rclpy's ~0.3 ms serialisation (which used to
count as node latency: at 16 cameras the last message left ~5 ms after the stamp). Printed:

- node latency: capture stamp -> ``~/tracks`` publish, measured inside the node (its
  ``/diagnostics`` median / p95 over the last 300 sets);
- end-to-end latency: capture stamp -> receipt of ``~/tracks`` by this process (adds DDS);
- node CPU: (user + system) CPU time of the node process over the run / wall time, in % of
  one core (from /proc), the same per output set in ms, and ``Fusion.step``'s processing
  time per set (what is left of the CPU per set is the node's own path: DDS, executor,
  decoding, output messages);
- the output rate and the sets emitted / partial.

With ``--runs N`` each configuration runs N times and the run with the lowest node latency
median is printed (the machine is shared). ``--markers`` also subscribes to ``~/markers``
(as RViz would), so their cost is included.

``--micro`` instead times the node's message paths in this process, without DDS, per
configuration: input decoding (CDR -> validated [P, J, 3]) by ``decode_person2d_array`` vs
rclpy's deserialiser + ``person2d_array_to_numpy``, and the outputs ``tracks_to_cdr`` vs
``tracks_to_msg`` + rclpy serialisation, ``tracks_to_markers_cdr`` vs ``tracks_to_markers`` +
serialisation (median of repeated calls, microseconds).

``--real SOURCE:CAMS@HZ,...`` replays real detections instead of the synthetic scene, looped
forwards and backwards (so motion stays continuous), converted to coco17 as pose2d publishes
them: ``pose2sim`` (OpenPose BODY_25B of the Pose2Sim session, 4 portrait cameras, 2 people)
or ``panoptic`` (the CMU Panoptic band1 3D ground truth of 3 people, 20 frames, through the
simulated detector into CAMS of its HD cameras), read in place from ``../shared/data``. It
prints the node's CPU share, sets/s and the latency medians; ``--base CHECKOUT`` runs every
configuration also with the fusion_node of another checkout (e.g. a ``git worktree`` of an
older commit) and prints both lines, runs interleaved.

Usage: ``python bench/bench_fusion_node.py [--seconds 10] [--configs 5x4,16x6] [--rate 30]
[--runs 2] [--markers] [--micro]``, or ``python bench/bench_fusion_node.py --real
panoptic:4@10,panoptic:5@30 --seconds 20 [--base /tmp/old_checkout]``
"""

import argparse
import os
import struct
import sys
import tempfile
import time
from typing import Any, Callable

from diagnostic_msgs.msg import DiagnosticArray
from mv3dpose_msgs.msg import Person2DArray, TrackedSkeletonArray
from mv3dpose_ros.core.diagnostic_keys import FusionKeys as K, FusionStatusNames as N
from mv3dpose_ros.core.geometry.calibration import save_rig_yaml
from mv3dpose_ros.ros.messages import numpy_to_person2d_array
from mv3dpose_ros.ros.qos import reliable_qos
from mv3dpose_ros.sim.people import WalkConfig
from mv3dpose_ros.sim.rig import RigConfig
from mv3dpose_ros.sim.scene import make_scene
from mv3dpose_ros.testing.probe import all_matched, Probe
from mv3dpose_ros.testing.processes import NodeProcess
from mv3dpose_ros.testing.stats import percentile
import numpy as np
from rclpy.serialization import deserialize_message, serialize_message
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray
import yaml

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TICKS = os.sysconf('SC_CLK_TCK')
STAMP = struct.Struct('<iI')     # header.stamp, right after the 4-byte CDR encapsulation
DATA = os.path.join(ROOT, '..', 'shared', 'data')
#: Panoptic HD cameras used by --real panoptic, in this order (the first 5 are bench/accuracy's).
PANOPTIC_CAMERAS = ['00_03', '00_06', '00_12', '00_13', '00_23', '00_01', '00_09', '00_16',
                    '00_19', '00_27']


def cpu_seconds(pid: int) -> float:
    """Return user + system CPU seconds of process ``pid`` (Linux /proc)."""
    with open(f'/proc/{pid}/stat') as f:
        fields = f.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / TICKS


def _scene(cams: int, people: int, frames: int, rate: float, seed: int) -> Any:
    radius = 6.0 if people <= 8 else 9.0
    return make_scene(num_cameras=cams, num_people=people, num_frames=frames, fps=rate,
                      seed=seed, rig=RigConfig(num_cameras=cams, radius_m=radius),
                      walk=WalkConfig(area_radius_m=radius * 0.5))


class Feed:
    """What the feeder publishes: cameras, per-frame 2D poses per camera, their layout."""

    def __init__(self, name: str, cameras: dict, views: list, layout: str,
                 people: int) -> None:
        self.name, self.cameras, self.views = name, cameras, views
        self.layout, self.people = layout, people

    def frame(self, index: int) -> dict:
        """Return the views of frame ``index``, looped forwards and backwards."""
        n = len(self.views)
        k = index % max(1, 2 * n - 2)
        return self.views[k if k < n else 2 * n - 2 - k]


def synthetic_feed(cams: int, people: int, frames: int, rate: float, seed: int = 0) -> Feed:
    """Return the synthetic scene of ``cams`` cameras and ``people`` people as a Feed."""
    scene = _scene(cams, people, frames, rate, seed)
    return Feed(f'synthetic {cams} x {people}', scene.cameras, scene.views, scene.layout,
                people)


def real_feed(source: str, cams: int) -> Feed:
    """Return real detections (``pose2sim`` or ``panoptic``) as a coco17 Feed of ``cams``."""
    from mv3dpose_ros.core.geometry.calibration import load_calibration
    from mv3dpose_ros.core.skeleton import convert_poses
    from mv3dpose_ros.io.datasets import load_panoptic_gt
    from mv3dpose_ros.io.openpose import match_camera_folders, OpenPoseSequence
    from mv3dpose_ros.sim.detector import detect
    if source == 'pose2sim':
        folder = os.path.join(DATA, 'pose2sim_multiperson')
        cameras = load_calibration(os.path.join(ROOT, 'config', 'rigs',
                                                'pose2sim_multiperson.yaml'))
        if not 2 <= cams <= len(cameras):
            raise SystemExit(f'pose2sim has {len(cameras)} cameras, asked for {cams}')
        cameras = dict(list(cameras.items())[:cams])
        folders, missing = match_camera_folders(os.path.join(folder, 'pose'), list(cameras))
        if missing:
            raise SystemExit(f'pose2sim: no detections for {missing} under {folder}')
        raw = [views for _, views in OpenPoseSequence(folders, num_joints=25)]
        src = 'body25b'
    elif source == 'panoptic':
        folder = os.path.join(DATA, 'panoptic_160906_band1')
        names = PANOPTIC_CAMERAS[:cams]
        if len(names) < max(2, cams):
            raise SystemExit(f'panoptic: at most {len(PANOPTIC_CAMERAS)} cameras')
        cameras = load_calibration(os.path.join(folder, 'calibration_160906_band1.json'),
                                   cameras=names)
        _, poses = load_panoptic_gt(os.path.join(folder, 'hdPose3d_stage1_coco19')).as_array()
        raw, _ = detect(cameras, poses[..., :3], 'panoptic19', seed=0)
        src = 'panoptic19'
    else:
        raise SystemExit(f'unknown source {source!r} (pose2sim or panoptic)')
    views = [{c: convert_poses(v[c], src, 'coco17') for c in cameras} for v in raw]
    people = int(np.median([max(len(p) for p in v.values()) for v in views]))
    return Feed(f'{source} {cams} cams', cameras, views, 'coco17', people)


def _time_us(fn: Callable[[], Any], repeat: int = 200) -> float:
    """Return the median wall time of ``fn()`` in microseconds (after one warm-up call)."""
    fn()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)) * 1e6


def micro(cams: int, people: int, rate: float, seed: int = 0) -> None:
    """Print the in-process cost of the node's message paths (no DDS)."""
    # Imported here so that the DDS benchmark also runs against older trees (A/B runs with
    # PYTHONPATH pointing at another checkout).
    from mv3dpose_ros.core.fusion.pipeline import Fusion
    from mv3dpose_ros.core.skeleton import get_layout
    from mv3dpose_ros.ros.markers import tracks_to_markers, tracks_to_markers_cdr
    from mv3dpose_ros.ros.messages import (decode_person2d_array, ns_to_stamp,
                                           person2d_array_to_numpy, tracks_to_cdr, tracks_to_msg)
    scene = _scene(cams, people, 40, rate, seed)
    layout = get_layout(scene.layout)
    fusion = Fusion(scene.cameras, layout)
    for f in range(len(scene.views)):
        tracks = fusion.step(scene.views[f], f / rate)
    cam = next(iter(scene.cameras))
    data = serialize_message(numpy_to_person2d_array(
        scene.views[-1][cam], Header(frame_id=cam), cam, scene.cameras[cam].width,
        scene.cameras[cam].height, scene.layout))
    header = Header(stamp=ns_to_stamp(time.time_ns()), frame_id='map')
    j = layout.num_joints
    rows = [
        ('input, per message', lambda: person2d_array_to_numpy(decode_person2d_array(data), j),
         lambda: person2d_array_to_numpy(deserialize_message(data, Person2DArray), j)),
        ('~/tracks, per set', lambda: tracks_to_cdr(tracks, header, layout.name),
         lambda: serialize_message(tracks_to_msg(tracks, header, layout.name))),
        ('~/markers, per set', lambda: tracks_to_markers_cdr(tracks, layout.bones, header),
         lambda: serialize_message(tracks_to_markers(tracks, layout.bones, header)))]
    for name, fast, slow in rows:
        f_us, s_us = _time_us(fast), _time_us(slow)
        print(f'{cams:4d} x {people:<2d} {len(tracks)} tracks | {name:<20} | CDR {f_us:7.1f} us '
              f'| rclpy messages {s_us:7.1f} us | x{s_us / f_us:4.1f}', flush=True)


def run(feed: Feed, seconds: float, rate: float, markers: bool = False,
        node_tree: str = '') -> dict:
    """Feed ``feed`` at ``rate`` into a fusion_node process (``node_tree``: its checkout)."""
    frames = int(seconds * rate)
    warmup = int(3 * rate)             # at most 3 s until the first output (discovery)
    tmp = tempfile.mkdtemp(prefix='bench_fusion_node_')
    rig = os.path.join(tmp, 'rig.yaml')
    save_rig_yaml(feed.cameras, rig)
    over = os.path.join(tmp, 'override.yaml')
    with open(over, 'w') as f:
        yaml.safe_dump({'/**/fusion_node': {'ros__parameters': {
            'rig_config': rig, 'camera_ids': list(feed.cameras), 'layout': feed.layout,
            'sync': {'slop_s': 0.5 / rate}, 'diagnostics': {'period_s': 1.0}}}}, f)
    env = dict(os.environ)
    if node_tree:      # that checkout's package first; cwd there too (python puts '' first)
        env['PYTHONPATH'] = os.path.abspath(node_tree) + os.pathsep + env.get('PYTHONPATH', '')
    proc = NodeProcess(['fusion_node', '--ros-args', '--params-file',
                        os.path.join(ROOT, 'config', 'fusion.yaml'), '--params-file', over],
                       os.path.join(tmp, 'fusion_node.log'), env=env, new_session=False,
                       cwd=os.path.abspath(node_tree) if node_tree else None)
    probe = Probe('bench_feeder')
    node, ex = probe.node, probe.executor
    e2e, outputs, marker_count = [], [], [0]

    def on_tracks(data: bytes) -> None:       # raw: the stamp is read from the CDR bytes
        sec, nanosec = STAMP.unpack_from(data, 4)
        e2e.append((time.time_ns() - sec * 1_000_000_000 - nanosec) / 1e6)
        outputs.append(data)

    node.create_subscription(TrackedSkeletonArray, '/fusion_node/tracks', on_tracks,
                             reliable_qos(100), raw=True)
    diags = probe.subscribe(DiagnosticArray, '/diagnostics', reliable_qos(20))
    if markers:
        def on_markers(data: bytes) -> None:
            marker_count[0] += 1

        node.create_subscription(MarkerArray, '/fusion_node/markers', on_markers,
                                 reliable_qos(100), raw=True)
    try:
        pubs = probe.camera_publishers(Person2DArray, feed.cameras, qos=reliable_qos(10))
        probe.spin_until(lambda: all_matched(pubs.values()), 60, [proc], 0.05)
        # Serialise beforehand so the feeder's own cost stays small; stamps patched at send.
        msgs = [{c: bytearray(serialize_message(numpy_to_person2d_array(
                    v, Header(frame_id=c), c, feed.cameras[c].width, feed.cameras[c].height,
                    feed.layout))) for c, v in feed.frame(f).items()}
                for f in range(warmup + frames)]
        period = 1.0 / rate

        def send(f: int) -> None:
            sec, nanosec = divmod(time.time_ns(), 1_000_000_000)
            for c, data in msgs[f].items():
                STAMP.pack_into(data, 4, sec, nanosec)
                pubs[c].publish(bytes(data))

        def wait_until(t: float) -> None:
            while True:
                left = t - time.monotonic()
                if left <= 0:
                    return
                ex.spin_once(timeout_sec=min(left, 0.005))

        # Warm-up: stream until the first output arrived (all endpoints matched).
        next_t = time.monotonic()
        first = 0
        while not e2e and first < warmup:
            send(first)
            first += 1
            next_t += period
            wait_until(next_t)
        if not e2e:
            raise RuntimeError(f'no output within {warmup} warm-up frames:\n' + proc.log())
        e2e.clear()
        outputs.clear()
        marker_count[0] = 0
        cpu0, wall0 = cpu_seconds(proc.pid), time.monotonic()
        next_t = time.monotonic()
        for f in range(first, first + frames):
            send(f)
            next_t += period
            wait_until(next_t)
        cpu1, wall1 = cpu_seconds(proc.pid), time.monotonic()   # over the feed only
        sent_outputs = len(e2e)
        end = time.monotonic() + 2.0
        while time.monotonic() < end and len(e2e) < frames:
            ex.spin_once(timeout_sec=0.02)
        diags.clear()
        end = time.monotonic() + 3.0
        while time.monotonic() < end and not any(
                s.name.endswith(N.TRACKING) for a in diags for s in a.status):
            ex.spin_once(timeout_sec=0.05)
    finally:
        proc.interrupt(10)
        probe.close()
    values = {}
    for arr in diags:
        for s in arr.status:
            if s.name.endswith(N.TRACKING) or s.name.endswith('synchronizer'):
                values.update({kv.key: kv.value for kv in s.values})
    lat = np.array(e2e[5:]) if len(e2e) > 10 else np.array(e2e)
    tracks = [len(deserialize_message(d, TrackedSkeletonArray).skeletons) for d in outputs[-30:]]
    cpu_s = cpu1 - cpu0
    return {'cams': len(feed.cameras), 'people': feed.people, 'frames': frames,
            'received': len(e2e), 'sets_per_s': sent_outputs / (wall1 - wall0),
            'node_median_ms': values.get(K.LATENCY_MEDIAN_MS, 'n/a'),
            'node_p95_ms': values.get(K.LATENCY_P95_MS, 'n/a'),
            'proc_median_ms': values.get(K.PROCESSING_MEDIAN_MS, 'n/a'),
            'proc_p95_ms': values.get(K.PROCESSING_P95_MS, 'n/a'),
            'e2e_median_ms': percentile(lat, 50), 'e2e_p95_ms': percentile(lat, 95),
            'cpu_pct': 100.0 * cpu_s / (wall1 - wall0),
            'cpu_ms_per_set': 1e3 * cpu_s / max(1, len(e2e)),
            'markers': marker_count[0],
            'sets': values.get(K.SETS_EMITTED, 'n/a'), 'partial': values.get(K.PARTIAL_SETS),
            'mean_tracks': float(np.mean(tracks)) if tracks else 0.0}


def _median(r: dict) -> float:
    try:
        return float(r['node_median_ms'])
    except (TypeError, ValueError):
        return float('inf')


def limits(cams: int = 4, persons: int = 2000, rate: float = 30.0) -> None:
    """
    Print what one oversized input costs fusion_node (dropped) and the step at the limits.

    A FusionNode is built in this process; ``_on_persons`` gets the raw CDR as its raw
    subscription would. The oversized message is a valid Person2DArray of ``persons`` people
    (over ``limits.max_persons``): the time is its whole path to the drop. Then every camera
    sends ``limits.max_persons`` people (the most a set can hold) and ``Fusion.step`` on that
    set is timed: the worst case per set at the default limits.
    """
    import rclpy
    from rclpy.parameter import Parameter
    from mv3dpose_ros.core.geometry.calibration import save_rig_yaml
    from mv3dpose_ros.nodes.fusion.node import FusionNode
    import tempfile
    scene = _scene(cams, 3, 2, rate, 0)
    rig = os.path.join(tempfile.mkdtemp(), 'rig.yaml')
    save_rig_yaml(scene.cameras, rig)
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    node = FusionNode(context=ctx, parameter_overrides=[
        Parameter('rig_config', value=rig), Parameter('log_throttle_s', value=60.0)])
    try:
        cam = next(iter(scene.cameras))
        rng = np.random.default_rng(0)
        c = scene.cameras[cam]
        j = 17

        def crowd(n):
            poses = np.stack([rng.uniform(0, c.width, (n, j)), rng.uniform(0, c.height, (n, j)),
                              rng.uniform(0.3, 1.0, (n, j))], axis=-1)
            return poses

        for n in (persons, 400):      # over the byte limit; under it but over max_persons
            big = bytes(serialize_message(numpy_to_person2d_array(
                crowd(n), Header(stamp=ns_to_stamp_(time.time_ns()), frame_id=cam), cam,
                c.width, c.height, scene.layout)))
            node.cams[cam].rejected.clear()
            times = []
            for _ in range(20):
                t0 = time.perf_counter()
                node.on_persons(cam, big)
                times.append(time.perf_counter() - t0)
            print(f'{n} persons ({len(big)} bytes) on {cam}: dropped in median '
                  f'{np.median(times) * 1e3:.2f} ms, max {max(times) * 1e3:.2f} ms over '
                  f'{len(times)} messages; rejected {dict(node.cams[cam].rejected)}',
                  flush=True)
        limit = node.params.limits.max_persons
        views = {cm: crowd(limit) for cm in scene.cameras}
        steps = []
        for k in range(5):
            t0 = time.perf_counter()
            node.fusion.step(views, 1000.0 + k / rate)
            steps.append(time.perf_counter() - t0)
        print(f'worst case at the limits ({cams} cameras x {limit} persons, random poses): '
              f'Fusion.step median {np.median(steps) * 1e3:.1f} ms, max '
              f'{max(steps) * 1e3:.1f} ms', flush=True)
    finally:
        node.destroy_node()
        rclpy.shutdown(context=ctx)


def ns_to_stamp_(ns: int):
    """Return a builtin_interfaces Time (local helper; the messages module's needs rclpy)."""
    from mv3dpose_ros.ros.messages import ns_to_stamp
    return ns_to_stamp(ns)


def real(args: argparse.Namespace) -> int:
    """Replay real detections (``--real``), optionally A/B against ``--base``; print rows."""
    trees = [('base', args.base), ('this', '')] if args.base else [('this', '')]
    print(f'fusion_node on real detections: {args.seconds:g} s per run, median of '
          f'{args.runs} run(s) per tree (interleaved), markers '
          f'{"subscribed" if args.markers else "off"}, {os.cpu_count()} CPUs (shared machine)'
          + (f'; base = {args.base}' if args.base else ''))
    print('source        cams @ Hz people | tree | node CPU % of one core (ms per set) | '
          'sets/s | node latency median ms | end-to-end median / p95 ms | tracks')
    for item in args.real.split(','):
        source, spec = item.split(':')
        cams, rate = spec.split('@')
        feed = real_feed(source, int(cams))
        rate = float(rate)
        results: dict = {name: [] for name, _ in trees}
        for _ in range(max(1, args.runs)):
            for name, tree in trees:
                results[name].append(run(feed, args.seconds, rate, markers=args.markers,
                                         node_tree=tree))
        for name, _ in trees:
            rs = results[name]

            def med(key: str) -> float:
                vals = []
                for r in rs:
                    try:
                        vals.append(float(r[key]))
                    except (TypeError, ValueError):
                        pass
                return float(np.median(vals)) if vals else float('nan')

            per_run = ', '.join(f'{r["cpu_pct"]:.1f}' for r in rs)
            print(f'{source:<13} {len(feed.cameras):4d} @ {rate:<4g} {feed.people:4d} | '
                  f'{name:<4} | {med("cpu_pct"):5.1f} ({med("cpu_ms_per_set"):4.2f})'
                  f'                    | {med("sets_per_s"):5.1f}  | {med("node_median_ms"):6.2f}'
                  f'                 | {med("e2e_median_ms"):6.2f} / {med("e2e_p95_ms"):<6.2f}'
                  f'               | {med("mean_tracks"):.1f}   '
                  f'(CPU % per run: {per_run})',
                  flush=True)
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--seconds', type=float, default=10.0)
    parser.add_argument('--rate', type=float, default=30.0)
    parser.add_argument('--configs', default='5x4,16x6', help='CAMSxPEOPLE,...')
    parser.add_argument('--runs', type=int, default=1,
                        help='runs per configuration; the lowest latency median is printed')
    parser.add_argument('--markers', action='store_true',
                        help='also subscribe to ~/markers (as RViz would)')
    parser.add_argument('--micro', action='store_true',
                        help='time the message paths in-process instead (no DDS)')
    parser.add_argument('--limits', action='store_true',
                        help='time the drop of a 2,000-person message and the step at the '
                             'input limits (in-process)')
    parser.add_argument('--real', default='',
                        help='SOURCE:CAMS@HZ,... real detections (pose2sim, panoptic) instead')
    parser.add_argument('--base', default='',
                        help='with --real: also run the fusion_node of this checkout (A/B)')
    args = parser.parse_args()
    # A DDS domain of its own: other fusion_nodes on this host (a rig, a benchmark) must not
    # feed or answer this one.
    os.environ.setdefault('ROS_DOMAIN_ID', str(50 + os.getpid() % 50))
    if args.limits:
        limits()
        return 0
    if args.micro:
        print('node message paths in-process (median per call; shared machine)')
        for item in args.configs.split(','):
            micro(*(int(v) for v in item.lower().split('x')), args.rate)
        return 0
    if args.real:
        return real(args)
    print(f'fusion_node benchmark: {args.rate:g} Hz, {args.seconds:g} s per configuration, '
          f'best of {args.runs} run(s), markers {"subscribed" if args.markers else "off"}, '
          f'{os.cpu_count()} CPUs (shared machine: figures vary with load)')
    print('cams x people | node latency median / p95 ms | end-to-end median / p95 ms | '
          'processing median / p95 ms | node CPU % of one core (ms per set) | output sets | '
          'tracks')
    for item in args.configs.split(','):
        cams, people = (int(v) for v in item.lower().split('x'))
        feed = synthetic_feed(cams, people, int((args.seconds + 3) * args.rate), args.rate)
        r = min((run(feed, args.seconds, args.rate, markers=args.markers)
                 for _ in range(max(1, args.runs))), key=_median)
        print(f'{cams:4d} x {people:<2d}     | {r["node_median_ms"]:>6} / {r["node_p95_ms"]:<6}'
              f'            | {r["e2e_median_ms"]:6.1f} / {r["e2e_p95_ms"]:<6.1f}'
              f'           | {r["proc_median_ms"]:>6} / {r["proc_p95_ms"]:<6}'
              f'           | {r["cpu_pct"]:5.1f} ({r["cpu_ms_per_set"]:4.1f})'
              f'                    | {r["received"]}/{r["frames"]} ({r["partial"]} partial)'
              f'{", %d marker arrays" % r["markers"] if args.markers else ""} | '
              f'{r["mean_tracks"]:.1f}', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
