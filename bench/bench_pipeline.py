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
Benchmark the whole live image path: N HD cameras -> mv3dpose_bringup -> tracks.

The cameras show the real 1920x1080 Panoptic frames of ``../shared/data/panoptic_demo``
(camera i of the rig its own view), looped; ``mv3dpose_bringup`` runs one ``pose2d_node`` per
camera and ``fusion_node`` with the shipped params files, exactly as a user starts it. Two ways
to play the cameras:

**In-process** (the default): this process publishes the frames free-running at ``--rate`` Hz
as ``sensor_msgs/Image`` (bgr8, best effort, the stamp = wall clock at publish = capture
time), each time point held ``--hold-s`` seconds. Printed per camera count and execution
provider:

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

**``--publishers``** (a live rig as a user runs it): one ``mv3dpose_image_publisher`` process
per camera publishes the frames at ``--rate`` on capture instants of the system clock (not
paced by anyone, no sim time). ``--compressed``, ``--video``, ``--portrait``, ``--people``,
``--max-wait-s`` and ``--logs`` imply it. A probe (``mv3dpose_ros.testing.rig``) records every
``persons_2d`` (which images inference processed, and when), every ``~/tracks`` message and
``/diagnostics``. Printed at the end:

- sets emitted among the time points inference could process (>= 2 cameras' ``persons_2d``;
  a time point groups stamps within half the inference period, see ``time_points``), also
  among those whose inference skew between cameras stayed within ``sync.max_wait_s``;
- per camera: frames published / skipped, received and dropped by pose2d (newer image
  arrived = overload), dropped or rejected by fusion, by reason;
- capture -> tracks latency (probe receipt - capture stamp) p50 / p95, and when the first
  tracks message with N confirmed people arrived.

``--video`` replays a recorded video rig instead: each camera's frames are first written as an
MPEG-4 video (each time point ``--hold`` s long; kept in the temp folder for the next run) and
the publishers read the videos, as a user replays the videos of a recorded rig.

``--portrait`` makes portrait cameras of them: each frame's 9:16 window around the people
is scaled to 1080x1920 (people upright, as a phone or a camera mounted for portrait records
them) with the matching intrinsics, so the same real scene runs through the portrait model
sizes. (Turning the frames a quarter turn instead would lay the people on their side: the
model finds 0-2 of the 3 then.)

    python bench/bench_pipeline.py [--cameras 1 2 4] [--rate 10] [--seconds 20] [--hold-s 2]
        [--providers auto] [--pose2d-param model.input_size:=384x640 ...]
    python bench/bench_pipeline.py --publishers [--cameras 4] [--rate 10] [--duration 60]
        [--hold 0] [--compressed jpeg] [--video] [--portrait]

(``--seconds`` and ``--duration``, ``--hold-s`` and ``--hold`` are the same options; their
defaults are those of the way the cameras are played: 20 s and 2 s in-process, 60 s and 0 s
with publishers; ``--cameras`` 1 2 4 and 4, ``--warmup`` 5 s after the first tracks and 10 s
after every camera answered.) ``test/test_live_rig.py`` runs the ``--publishers`` rig, shorter,
and asserts on the same figures. Nothing here is asserted: the figures go to
``docs/benchmarks.md`` with the load (uptime) of the run.
"""

import argparse
import os
import struct
import sys
import tempfile
import time
from typing import Dict, List, Sequence, Tuple

from mv3dpose_ros.core.diagnostic_keys import FusionKeys as K, Pose2DKeys as P
from mv3dpose_ros.core.types import NS_PER_S as NS

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.path.join(os.path.dirname(ROOT), 'shared', 'data', 'panoptic_demo')
CALIBRATION = os.path.join(DATA, 'camera_parameters.json')
RIG = os.path.join(ROOT, 'config', 'rigs', 'panoptic_demo.yaml')
CAMERAS = ('00_03', '00_06', '00_12', '00_13', '00_23')
FRAMES = ('00004500', '00005514', '00006859', '00009348', '00013007')
STAMP = struct.Struct('<iI')     # header.stamp, right after the 4-byte CDR encapsulation
STAGES = ('transport', 'wait', 'decode', 'pre', 'inference', 'post', 'publish')
# The options of each way to play the cameras: (in-process default, --publishers default).
DEFAULTS = {'cameras': ([1, 2, 4], [4]), 'seconds': (20.0, 60.0), 'warmup': (5.0, 10.0),
            'hold': (2.0, 0.0)}
RIG_ONLY = ('compressed', 'video', 'portrait', 'people', 'max_wait_s', 'logs')


# ----------------------------------------------------------------- in-process: this process plays

def _load_frames(cameras: List[str]) -> Dict[str, list]:
    import cv2
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
    pipeline = [v for v in diags.values() if K.SETS_EMITTED in v]

    def fusion(key: str) -> int:
        return int(float(pipeline[0].get(key, 0))) if pipeline else 0

    return {
        'received': sum(int(d.get(P.IMAGES_RECEIVED, 0)) for d in pose),
        'dropped_pose2d': sum(int(d.get(P.DROPPED_NEWER, 0))
                              for d in pose),
        'dropped_sync': sum(int(d.get(K.DROPPED_BY_SYNC, 0)) for d in diags.values()),
        'sets emitted': fusion('sets emitted'), 'partial sets': fusion('partial sets'),
        'skip decided': fusion('incomplete sets decided on skip notices'),
    }


def _node_command(cameras: List[str], params: List[str], fusion_params: Sequence[str],
                  tmp: str) -> List[str]:
    """Return bringup's command (one camera: pose2d_node alone, as bringup would start it)."""
    if len(cameras) > 1:
        cmd = ['mv3dpose_bringup', '--rig', RIG, '--cameras', *cameras]
        for p in params:
            cmd += ['--pose2d-param', p]
        for p in fusion_params:
            cmd += ['--fusion-param', p]
        return cmd
    import yaml
    from mv3dpose_ros.nodes.processes import parse_assignments, rig_processes
    plan = rig_processes([os.path.join(ROOT, 'config', 'pose2d.yaml')], RIG, cameras,
                         pose2d_params=parse_assignments(params, '--pose2d-param'),
                         fusion=False)
    over = os.path.join(tmp, 'pose2d.yaml')
    with open(over, 'w') as f:
        yaml.safe_dump(plan.overrides(), f)
    (pose2d,) = plan.processes
    return [pose2d.executable] + pose2d.ros_args(plan.params_files + [over])


def run(cameras: List[str], rate: float, seconds: float, hold_s: float, provider: str,
        pose2d_params: List[str], warmup_s: float, verbose: bool,
        fusion_params: Sequence[str] = (), latency_log: str = '') -> dict:
    """Start bringup, play the cameras, collect tracks and diagnostics; return the figures."""
    from diagnostic_msgs.msg import DiagnosticArray
    from mv3dpose_msgs.msg import Person2DArray, TrackedSkeletonArray
    from mv3dpose_ros.ros.images import numpy_to_image
    from mv3dpose_ros.ros.messages import stamp_to_ns
    from mv3dpose_ros.ros.names import camera_topic
    from mv3dpose_ros.ros.qos import reliable_qos, sensor_qos
    from mv3dpose_ros.testing.probe import all_matched, Probe
    from mv3dpose_ros.testing.processes import NodeProcess
    from mv3dpose_ros.testing.stats import median, percentile
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import Image
    from std_msgs.msg import Header

    frames = _load_frames(cameras)
    wires = {c: [bytearray(serialize_message(numpy_to_image(img, Header(frame_id=c), 'bgr8')))
                 for img in imgs] for c, imgs in frames.items()}
    tmp = tempfile.mkdtemp(prefix='bench_pipeline_')
    params = [f'model.providers:={provider}'] + list(pose2d_params)
    proc = NodeProcess(_node_command(cameras, params, fusion_params, tmp),
                       os.path.join(tmp, 'bringup.log'), cwd=ROOT)
    # The receiving side spins in its own thread, so that publishing 6 MB images does not
    # delay the receipt of the outputs (latency is also read from the nodes' own diagnostics,
    # measured where the output is published).
    outputs = Probe('bench_pipeline_outputs')
    feeder = Probe('bench_pipeline_publisher', context=outputs.context)
    ex = feeder.executor
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
        outputs.node.create_subscription(TrackedSkeletonArray, '/fusion_node/tracks', on_tracks,
                                         reliable_qos(50))
    else:
        outputs.node.create_subscription(
            Person2DArray, camera_topic('/{camera}/persons_2d', cameras[0]), on_tracks,
            reliable_qos(50))
    outputs.node.create_subscription(DiagnosticArray, '/diagnostics', on_diag,
                                     reliable_qos(50))
    outputs.start_spinning()
    pubs = feeder.camera_publishers(Image, cameras, '/{camera}/image_raw',
                                    sensor_qos('best_effort', 1))
    published = 0
    try:
        if not feeder.spin_until(lambda: all_matched(pubs.values()), 120, [proc], 0.05):
            raise RuntimeError('pose2d nodes did not subscribe within 120 s:\n'
                               + proc.tail(3000))
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
                raise RuntimeError('no tracks after the warm-up:\n' + proc.tail(3000))
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
        feeder.spin_for(1.5)                     # let the last diagnostics arrive
    finally:
        proc.interrupt(30)
        time.sleep(0.1)
        feeder.close()
        outputs.close()
    pose = [v for k, v in diags.items() if k.endswith(' inference')]
    stage = {s: median([float(d.get(P.STAGE_MEDIAN_MS.format(s), 'nan')) for d in pose])
             for s in STAGES}
    fusion = [v for k, v in diags.items() if K.PROCESSING_MEDIAN_MS in v]
    stage['fusion'] = median([float(d['processing median (ms)']) for d in fusion])
    if len(cameras) > 1:         # capture stamp -> ~/tracks published, inside fusion_node
        inside = (median([float(d['latency median (ms)']) for d in fusion]),
                  median([float(d['latency p95 (ms)']) for d in fusion]))
    else:                        # capture stamp -> persons_2d published, inside pose2d_node
        inside = (median([float(d.get(P.CAPTURE_TO_PUBLISH_MEDIAN_MS, 'nan')) for d in pose]),
                  median([float(d.get(P.CAPTURE_TO_PUBLISH_P95_MS, 'nan')) for d in pose]))
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
        'p50': percentile(latency, 50), 'p95': percentile(latency, 95), 'inside': inside,
        'stage': stage, 'published_images': published * len(cameras),
        'whole': whole, 'window': window_counts, 'seconds': window,
        'people': {p: (sum(1 for n in v if n >= 3), len(v), min(v)) for p, v in
                   sorted(per_point.items())},
        'threads': [d.get(P.THREADS, '?') for d in pose][:1],
        'input': sorted({d.get(P.INPUT_SIZE, '?') + ' ' + d.get(P.PRECISION, '')
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


# --------------------------------------------------- --publishers: image publisher processes play

def portrait_rig(cams: Sequence[str]) -> Tuple[str, str]:
    """
    Write the Panoptic cameras as portrait 1080x1920 cameras; return (frames, rig YAML).

    Each frame's 9:16 window (608 x 1080 px) centred on the people (the median centre of the
    people the default 2D model finds in the camera's frames) is scaled to 1080 x 1920, as a
    portrait camera would see them, upright. The intrinsics follow the crop and the scale
    (``cv2.resize``'s pixel centres); distortion and pose stay, being in normalised
    coordinates. People near the edges of a view may be cut, as in a real portrait rig.
    """
    import cv2
    import numpy as np
    from mv3dpose_ros.core.geometry.calibration import load_calibration, save_rig_yaml
    from mv3dpose_ros.core.geometry.camera import Camera
    from mv3dpose_ros.pose2d.estimator import open_estimator
    from mv3dpose_ros.pose2d.models import resolve_model_path
    folder = os.path.join(tempfile.gettempdir(), 'bench_rig_portrait')
    rig = load_calibration(CALIBRATION, cameras=cams)
    estimator = open_estimator(resolve_model_path('yolo11n-pose', '384x640'), threads=1)
    out_w, out_h = 1080, 1920
    portrait = {}
    for cam, c in rig.items():
        crop_w = int(round(c.height * out_w / out_h))
        images = {name: cv2.imread(os.path.join(DATA, cam, name))
                  for name in sorted(os.listdir(os.path.join(DATA, cam)))}
        images = {name: image for name, image in images.items() if image is not None}
        centres = []
        for image in images.values():
            found = estimator.infer(image)
            centres += [(b[0] + b[2]) / 2 for b, p in zip(found.boxes, found.scores) if p >= 0.5]
        u = float(np.median(centres)) if centres else c.width / 2
        x0 = int(min(max(0, round(u - crop_w / 2)), c.width - crop_w))
        sx, sy = out_w / crop_w, out_h / c.height
        K = np.array(c.K, dtype=float)
        K[0] *= sx
        K[0, 2] = (c.K[0, 2] - x0 + 0.5) * sx - 0.5
        K[1] *= sy
        K[1, 2] = (c.K[1, 2] + 0.5) * sy - 0.5
        portrait[cam] = Camera(cam, K, c.dist, c.R, c.t, out_w, out_h)
        out = os.path.join(folder, cam)
        os.makedirs(out, exist_ok=True)
        for name, image in images.items():
            target = os.path.join(out, name)
            if not os.path.exists(target):
                cv2.imwrite(target, cv2.resize(image[:, x0:x0 + crop_w], (out_w, out_h),
                                               interpolation=cv2.INTER_LINEAR))
    path = os.path.join(folder, 'rig.yaml')
    save_rig_yaml(portrait, path, comment='Panoptic cameras as portrait cameras '
                                          '(bench_pipeline.py --portrait)')
    return folder, path


def make_videos(cams: Sequence[str], rate: float, hold: float,
                frames: str = DATA) -> Dict[str, str]:
    """Write each camera's Panoptic frames as an MPEG-4 video, each shown ``hold`` s."""
    import cv2
    kind = '_portrait' if frames != DATA else ''
    folder = os.path.join(tempfile.gettempdir(), f'bench_rig_videos{kind}_{rate:g}hz_{hold:g}s')
    os.makedirs(folder, exist_ok=True)
    repeat = max(1, int(round(hold * rate)))
    out = {}
    for cam in cams:
        out[cam] = path = os.path.join(folder, f'{cam}.mp4')
        if os.path.exists(path):
            continue
        part = os.path.join(folder, f'{cam}.part.mp4')
        writer = None
        for name in sorted(os.listdir(os.path.join(frames, cam))):
            image = cv2.imread(os.path.join(frames, cam, name))
            if image is None:
                continue
            if writer is None:
                writer = cv2.VideoWriter(part, cv2.VideoWriter_fourcc(*'mp4v'), rate,
                                         (image.shape[1], image.shape[0]))
            for _ in range(repeat):
                writer.write(image)
        writer.release()
        os.replace(part, path)
        print(f'bench_pipeline: wrote {path} ({repeat} frames per time point)', flush=True)
    return out


def shipped_max_wait() -> float:
    """Return ``sync.max_wait_s`` of config/fusion.yaml."""
    from mv3dpose_ros.io.params_file import node_parameters, read_params_file
    doc = read_params_file(os.path.join(ROOT, 'config', 'fusion.yaml'))
    return float(node_parameters([doc], 'fusion_node').get('sync', {}).get('max_wait_s', 0.1))


def run_rig(args: argparse.Namespace, n: int, pose2d_params: List[str]) -> None:
    """Run ``n`` cameras with one image publisher process each and print the figures."""
    from mv3dpose_ros.testing.processes import NodeProcess, stop_all
    from mv3dpose_ros.testing.rig import (analyse, drop_table, publisher_command, published_counts,
                                          RigProbe)
    cams = CAMERAS[:n]
    max_wait = args.max_wait_s
    for item in args.fusion_param:
        if item.startswith('sync.max_wait_s:='):
            max_wait = float(item.split(':=', 1)[1])
    if max_wait is None:
        max_wait = shipped_max_wait()
    frames, calibration = portrait_rig(cams) if args.portrait else (DATA, CALIBRATION)
    videos = make_videos(cams, args.rate, args.hold, frames) if args.video else {}
    logdir = args.logs or tempfile.mkdtemp(prefix='bench_rig_')
    os.makedirs(logdir, exist_ok=True)
    procs, logs = [], {}
    probe = RigProbe(cams)
    t_start = time.time_ns()

    def launch(cmd: List[str], name: str) -> NodeProcess:
        return NodeProcess(cmd, os.path.join(logdir, f'{name}.log'), cwd=ROOT)

    try:
        over = [a for p in args.fusion_param for a in ('--fusion-param', p)]
        over += [a for p in pose2d_params for a in ('--pose2d-param', p)]
        procs.append(launch(['mv3dpose_bringup', '--rig', calibration, '--cameras', *cams,
                             *over], 'bringup'))
        for cam in cams:
            logs[cam] = os.path.join(logdir, f'publisher_{cam}.log')
            hold = ['--hold', f'{args.hold:g}'] if args.hold and not videos else []
            procs.append(launch(publisher_command(cam, args.rate, args.compressed or '',
                                                  ['--wait-for-subscribers', '1', *hold],
                                                  videos.get(cam, ''), frames, calibration),
                                f'publisher_{cam}'))
        deadline = time.monotonic() + 120
        while probe.cameras_answering() < len(cams) and time.monotonic() < deadline:
            if not procs[0].alive():
                stop_all(procs[1:])
                probe.close()
                raise SystemExit(f'bringup exited with {procs[0].returncode}; see {logdir}')
            time.sleep(0.2)
        t_ready = time.time_ns()
        time.sleep(args.warmup + args.seconds + 2.0)
        t_end = time.time_ns() - 2 * NS
        first = probe.first_confirmed(args.people, t_start)
        share = probe.confirmed_share(args.people, t_ready + int(args.warmup * NS), t_end)
        names = sorted(os.listdir(os.path.join(DATA, cams[0])))
        by_point = probe.confirmed_by_time_point(
            t_ready + int(args.warmup * NS), t_end, int(args.hold * NS), len(names)
        ) if args.hold else {}
    finally:
        stop_all(procs[1:])
        stop_all(procs[:1])
        time.sleep(0.5)
    res = analyse(probe, t_ready + int(args.warmup * NS), t_end, max_wait)
    published = published_counts(logs)
    if args.verbose:
        with probe.lock:
            for (name, _), values in sorted(probe.status.items()):
                print(f'    {name}: {values}')
    probe.close()
    size = '1080x1920' if args.portrait else '1920x1080'
    print(f'{len(cams)} cameras x {size} {args.compressed or "bgr8"} at {args.rate:g} Hz, '
          f'{args.seconds:g} s measured after {args.warmup:g} s warm-up; bringup '
          f'{" ".join(args.fusion_param + pose2d_params) or "defaults"}; '
          f'{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}; logs in {logdir}')
    print(f'time points with persons_2d: {res["time_points_seen"]}, processable (>= 2 '
          f'cameras): {res["processable"]}, sets emitted: {res["emitted"]} '
          f'({res["emitted_pct"]:.1f} %)')
    print(f'inference skew between cameras p50 {res["skew_p50_ms"]:.0f} ms, p95 '
          f'{res["skew_p95_ms"]:.0f} ms; within sync.max_wait_s {max_wait:g} s: '
          f'{res["within_wait"]} time points, emitted {res["emitted_within_wait"]} '
          f'({res["emitted_within_wait_pct"]:.1f} %)')
    print(f'capture -> tracks latency p50 {res["latency_p50_ms"]:.0f} ms, p95 '
          f'{res["latency_p95_ms"]:.0f} ms (first tracks message of each of '
          f'{res["sets_with_tracks"]} sets; {res["tracks_messages"]} tracks messages in all)')
    print(f'first tracks with {args.people} confirmed people: '
          + (f'{first:.1f} s after start' if first is not None else 'never'))
    pct = f' ({100.0 * share[0] / share[1]:.1f} %)' if share[1] else ''
    held = (f'; each image held {args.hold:g} s' + (' (MPEG-4 videos)' if videos else '')
            if args.hold else
            '; the looped images change every instant (people jump between them)')
    print(f'tracks messages with {args.people} confirmed people in the measured window: '
          f'{share[0]} of {share[1]}{pct}{held}')
    print('  (confirmed, published skeletons): messages  '
          + ', '.join(f'{k}: {v}' for k, v in sorted(share[2].items())))
    for point, hist in sorted(by_point.items()):
        print(f'  time point {point} ({names[point]}): confirmed people -> messages  '
              + ', '.join(f'{k}: {v}' for k, v in sorted(hist.items())))
    print('per camera (whole run):')
    print('\n'.join(drop_table(probe, published)))


# ------------------------------------------------------------------------------------- command

def parse_args(argv=None) -> argparse.Namespace:
    """Parse the options; fill the defaults of the way the cameras are played."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--publishers', action='store_true',
                        help='play the cameras with one mv3dpose_image_publisher process each '
                             '(a rig as a user runs it) instead of from this process')
    parser.add_argument('--cameras', type=int, nargs='+', default=None,
                        help='camera counts to run (default 1 2 4; with --publishers 4)')
    parser.add_argument('--rate', type=float, default=10.0, help='publish rate per camera [Hz]')
    parser.add_argument('--seconds', '--duration', dest='seconds', type=float, default=None,
                        help='measured window [s] (default 20; with --publishers 60)')
    parser.add_argument('--warmup', type=float, default=None,
                        help='seconds after the first tracks (default 5), with --publishers '
                             'after every camera answered (default 10), before measuring')
    parser.add_argument('--hold-s', '--hold', dest='hold', type=float, default=None,
                        help='show each Panoptic time point this long [s] (5 time points; a '
                             'still scene per image, so tracks can persist) (default 2; with '
                             '--publishers 0: a new one every instant)')
    parser.add_argument('--providers', nargs='+', default=None,
                        help='execution providers to compare (default: every available one; '
                             'with --publishers: the shipped model.providers)')
    parser.add_argument('--pose2d-param', action='append', default=[], metavar='NAME:=VALUE',
                        help='passed to mv3dpose_bringup (e.g. inference_rate_hz:=2)')
    parser.add_argument('--fusion-param', action='append', default=[], metavar='NAME:=VALUE',
                        help='passed to mv3dpose_bringup (e.g. sync.max_wait_s:=0.5)')
    parser.add_argument('--verbose', action='store_true', help='print every diagnostic status')
    parser.add_argument('--latency-log', metavar='FILE', default='',
                        help='write each measured tracks message (receipt, latency, time point, '
                             'people) to FILE (the last run of several; in-process play only)')
    rig = parser.add_argument_group('--publishers only (each implies it)')
    rig.add_argument('--compressed', choices=('jpeg', 'png'), default=None)
    rig.add_argument('--max-wait-s', type=float, default=None,
                     help='sync.max_wait_s to judge skew (default: config/fusion.yaml)')
    rig.add_argument('--people', type=int, default=None,
                     help='confirmed people to wait for (default 3)')
    rig.add_argument('--logs', default=None, help='folder for the process logs')
    rig.add_argument('--video', action='store_true', default=None,
                     help='replay the frames as one MPEG-4 video per camera (each time '
                          'point --hold s long) instead of image folders')
    rig.add_argument('--portrait', action='store_true', default=None,
                     help="portrait cameras: each frame's 9:16 window around the people, "
                          'scaled to 1080x1920, with its calibration')
    args = parser.parse_args(argv)
    args.publishers = args.publishers or any(getattr(args, k) is not None for k in RIG_ONLY)
    if args.publishers and args.latency_log:
        parser.error('--latency-log goes with the in-process play, not --publishers')
    for key, (inline, publishers) in DEFAULTS.items():
        if getattr(args, key) is None:
            setattr(args, key, publishers if args.publishers else inline)
    args.people = 3 if args.people is None else args.people
    args.video, args.portrait = bool(args.video), bool(args.portrait)
    return args


def main(argv=None) -> int:
    """Run the configurations and print one block each."""
    args = parse_args(argv)
    if not os.path.isdir(DATA):
        print(f'bench_pipeline: skipped: no frames at {DATA}')
        return 0
    from mv3dpose_ros.testing.processes import ProcessDied
    if args.publishers:
        runs = [(p, [f'model.providers:={p}'] + args.pose2d_param)
                for p in args.providers] if args.providers else [(None, args.pose2d_param)]
        for n in args.cameras:
            for _, pose2d_params in runs:
                run_rig(args, n, pose2d_params)
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
                _print(run(cams, args.rate, args.seconds, args.hold, provider,
                           args.pose2d_param, args.warmup, args.verbose, args.fusion_param,
                           args.latency_log))
            except (RuntimeError, ProcessDied) as exc:
                print(f'{n} cam, {provider}: failed: {exc}', flush=True)
    print(f'bench_pipeline: load at the end {os.getloadavg()}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
