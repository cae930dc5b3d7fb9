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
A live rig as a user runs it: free-running image publishers -> mv3dpose_bringup -> tracks.

One ``mv3dpose_image_publisher`` process per camera publishes the real Panoptic frames (1080p,
looped) at ``--rate`` on capture instants of the system clock (not paced by anyone, no sim
time); ``mv3dpose_bringup`` starts one ``pose2d_node`` per camera and ``fusion_node`` with the
defaults. A probe records every ``persons_2d`` (which images inference processed, and when),
every ``~/tracks`` message and ``/diagnostics``. Printed at the end:

- sets emitted among the time points inference could process (>= 2 cameras' ``persons_2d``;
  a time point groups stamps within half the inference period, see ``time_points``), also
  among those whose inference skew between cameras stayed within ``sync.max_wait_s``;
- per camera: frames published / skipped, received and dropped by pose2d (newer image
  arrived = overload), dropped or rejected by fusion, by reason;
- capture -> tracks latency (probe receipt - capture stamp) p50 / p95, and when the first
  tracks message with N confirmed people arrived.

    python bench/bench_rig.py [--cameras 4] [--rate 10] [--duration 60] [--compressed jpeg]
                              [--video] [--portrait]

``--video`` replays a recorded video rig instead: each camera's frames are first written as an
MPEG-4 video (each time point ``--hold`` s long; kept in the temp folder for the next run) and
the publishers read the videos, as a user replays the videos of a recorded rig.

``--portrait`` makes portrait cameras of them: each frame's 9:16 window around the people
is scaled to 1080x1920 (people upright, as a phone or a camera mounted for portrait records
them) with the matching intrinsics, so the same real scene runs through the portrait model
sizes. (Turning the frames a quarter turn instead would lay the people on their side: the
model finds 0-2 of the 3 then.)

``test/test_live_rig.py`` runs the same rig, shorter, and asserts on the same figures.
"""

import argparse
import bisect
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from typing import Dict, List, Optional, Sequence, Tuple

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEMO = os.path.join(os.path.dirname(ROOT), 'shared', 'data', 'panoptic_demo')
CALIBRATION = os.path.join(DEMO, 'camera_parameters.json')
CAMERAS = ('00_03', '00_06', '00_12', '00_13', '00_23')
NS = 1_000_000_000


class Probe:
    """Record persons_2d, tracks and /diagnostics of a running rig (own rclpy context)."""

    def __init__(self, cameras: Sequence[str]) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        from diagnostic_msgs.msg import DiagnosticArray
        from mv3dpose_msgs.msg import Person2DArray, TrackedSkeletonArray
        from mv3dpose_ros.ros.names import camera_topic
        from mv3dpose_ros.ros.qos import reliable_qos

        self.cameras = list(cameras)
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('rig_probe', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.lock = threading.Lock()
        self.persons: Dict[int, Dict[str, int]] = {}      # stamp -> camera -> arrival ns
        self.people: Dict[int, Dict[str, int]] = {}       # stamp -> camera -> persons
        self.tracks: List[tuple] = []                     # (stamp, arrival, confirmed, total)
        self.status: Dict[tuple, dict] = {}               # (name, hardware_id) -> values
        for cam in self.cameras:
            self.node.create_subscription(
                Person2DArray, camera_topic('/{camera}/persons_2d', cam),
                lambda m, c=cam: self._on_persons(c, m), reliable_qos(50))
        self.node.create_subscription(TrackedSkeletonArray, '/fusion_node/tracks',
                                      self._on_tracks, reliable_qos(50))
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diag,
                                      reliable_qos(50))
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    @staticmethod
    def _stamp(header) -> int:
        return header.stamp.sec * NS + header.stamp.nanosec

    def _on_persons(self, cam: str, msg) -> None:
        now = time.time_ns()
        with self.lock:
            stamp = self._stamp(msg.header)
            self.persons.setdefault(stamp, {})[cam] = now
            self.people.setdefault(stamp, {})[cam] = len(msg.persons)

    def _on_tracks(self, msg) -> None:
        now = time.time_ns()
        confirmed = sum(s.state == s.CONFIRMED for s in msg.skeletons)
        with self.lock:
            self.tracks.append((self._stamp(msg.header), now, confirmed, len(msg.skeletons)))

    def _on_diag(self, msg) -> None:
        with self.lock:
            for st in msg.status:
                self.status[(st.name, st.hardware_id)] = {kv.key: kv.value for kv in st.values}

    def _spin(self) -> None:
        while not self._stop.is_set() and self.context.ok():
            self.executor.spin_once(timeout_sec=0.05)

    def first_confirmed(self, people: int, since_ns: int) -> Optional[float]:
        """Return seconds from ``since_ns`` to the first tracks with ``people`` confirmed."""
        with self.lock:
            hits = [t for _, t, c, _ in self.tracks if c >= people]
        return (min(hits) - since_ns) / NS if hits else None

    def confirmed_share(self, people: int, since_ns: int, until_ns: int
                        ) -> Tuple[int, int, Dict[Tuple[int, int], int]]:
        """
        Return tracks messages with >= ``people`` confirmed, all, and a histogram.

        Counts the messages arriving in the window; the histogram maps (confirmed, skeletons
        published) to how many messages had them.
        """
        with self.lock:
            window = [(c, n) for _, t, c, n in self.tracks if since_ns <= t <= until_ns]
        hist: Dict[Tuple[int, int], int] = {}
        for key in window:
            hist[key] = hist.get(key, 0) + 1
        return sum(c >= people for c, _ in window), len(window), hist

    def confirmed_by_time_point(self, since_ns: int, until_ns: int, slot_ns: int,
                                frames: int) -> Dict[int, Dict[int, int]]:
        """Per time point shown (stamp // slot mod frames): confirmed people -> messages."""
        with self.lock:
            window = [(s, c) for s, t, c, _ in self.tracks if since_ns <= t <= until_ns]
        out: Dict[int, Dict[int, int]] = {}
        for stamp, confirmed in window:
            hist = out.setdefault(stamp // slot_ns % frames, {})
            hist[confirmed] = hist.get(confirmed, 0) + 1
        return out

    def cameras_answering(self) -> int:
        """Return how many cameras have published persons_2d so far."""
        with self.lock:
            return len({c for cams in self.persons.values() for c in cams})

    def close(self) -> None:
        """Stop spinning and shut the context down."""
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.node.destroy_node()
        self.context.try_shutdown()

    def values(self, suffix: str) -> dict:
        """Return the latest diagnostics values of the status whose name ends with ``suffix``."""
        with self.lock:
            for (name, _), vals in self.status.items():
                if name.endswith(suffix):
                    return dict(vals)
        return {}


def time_points(persons: Dict[int, Dict[str, int]]) -> Dict[int, Dict[int, Dict[str, int]]]:
    """
    Group the inferred stamps into time points: ``{first stamp: {stamp: {camera: arrival}}}``.

    Cameras of one rig infer the same instants, but publishers that cannot keep up (a video
    decoded on a busy CPU) skip different instants, so a grid window's first image can be a
    frame or two apart between cameras, and ``fusion_node`` still makes one set of them (its
    slop is half the set period). Stamps closer than half of the shortest per-camera median
    step between inferred images are one time point, one stamp per camera; exact stamps
    otherwise.
    """
    steps = []
    for cam in {c for cams in persons.values() for c in cams}:
        mine = sorted(s for s, cams in persons.items() if cam in cams)
        if len(mine) > 2:
            steps.append(sorted(b - a for a, b in zip(mine, mine[1:]))[(len(mine) - 1) // 2])
    tolerance = min(steps) // 2 if steps else 0
    out: Dict[int, Dict[int, Dict[str, int]]] = {}
    first = None
    for stamp in sorted(persons):
        cams = persons[stamp]
        group = out.get(first) if first is not None else None
        if group is None or stamp - first >= tolerance or any(
                c in members for members in group.values() for c in cams):
            first = stamp
            out[first] = {}
        out[first][stamp] = cams
    return out


def analyse(probe: Probe, start_ns: int, end_ns: int, max_wait_s: float,
            min_views: int = 2) -> dict:
    """Figures of the time points (``time_points``) stamped within ``[start_ns, end_ns]``."""
    with probe.lock:
        inferred = {s: dict(c) for s, c in probe.persons.items() if start_ns <= s <= end_ns}
        tracks = [t for t in probe.tracks if start_ns <= t[0] <= end_ns]
    groups = time_points(inferred)
    persons = {first: {c: t for cams in g.values() for c, t in cams.items()}
               for first, g in groups.items()}
    spans = sorted((min(g), max(g), first) for first, g in groups.items())

    def point_of(stamp: int) -> Optional[int]:
        """Return the time point of a set stamp (the mean of its members' stamps)."""
        i = bisect.bisect_right(spans, (stamp, float('inf'), 0)) - 1
        return spans[i][2] if i >= 0 and spans[i][0] <= stamp <= spans[i][1] else None

    processable = {s: c for s, c in persons.items() if len(c) >= min_views}
    emitted = {point_of(t[0]) for t in tracks} - {None}
    skew = {s: (max(c.values()) - min(c.values())) / NS for s, c in processable.items()}
    within = [s for s in processable if skew[s] <= max_wait_s]
    first_arrival: Dict[int, int] = {}      # per set stamp (not idle / coasting updates)
    for stamp, arr, _, _ in tracks:
        if point_of(stamp) is not None:
            first_arrival.setdefault(stamp, arr)
    latency = sorted((arr - stamp) / 1e6 for stamp, arr in first_arrival.items())

    def pct(part: int, whole: int) -> float:
        return 100.0 * part / whole if whole else float('nan')

    def q(values: List[float], p: float) -> float:
        if not values:
            return float('nan')
        return values[min(len(values) - 1, int(round(p / 100.0 * (len(values) - 1))))]

    skews = sorted(skew.values())
    return {
        'time_points_seen': len(persons), 'processable': len(processable),
        'emitted': len(emitted & set(processable)),
        'emitted_pct': pct(len(emitted & set(processable)), len(processable)),
        'within_wait': len(within), 'emitted_within_wait': len(emitted & set(within)),
        'emitted_within_wait_pct': pct(len(emitted & set(within)), len(within)),
        'skew_p50_ms': q(skews, 50) * 1e3, 'skew_p95_ms': q(skews, 95) * 1e3,
        'latency_p50_ms': q(latency, 50), 'latency_p95_ms': q(latency, 95),
        'tracks_messages': len(tracks), 'sets_with_tracks': len(first_arrival),
        'missed': sorted(set(processable) - emitted),
    }


def drop_table(probe: Probe, published: Dict[str, str]) -> List[str]:
    """Return one line per camera: published, pose2d and fusion counts by reason."""
    lines = []
    for cam in probe.cameras:
        p2d = probe.values(f': {cam} inference')     # pose2d_node: <cam> inference
        fus = probe.values(f': {cam} input')         # fusion_node: <cam> input
        parts = [f'published {published.get(cam, "?")}']
        for key in ('Images received', 'Images processed'):
            if key in p2d:
                parts.append(f'pose2d {key.split()[-1]} {p2d[key]}')
        parts += [f'pose2d {k.lower()} {v}' for k, v in p2d.items()
                  if any(w in k.lower() for w in ('dropped', 'rejected', 'skipped'))]
        parts += [f'fusion {k} {v}' for k, v in fus.items()
                  if any(w in k for w in ('dropped', 'late', 'rejected', 'outlier', 'lost',
                                          'missing', 'skipped')) and v not in ('0', '0.0')]
        lines.append(f'  {cam}: ' + ', '.join(parts))
    return lines


def publisher_command(cam: str, rate: float, compressed: str = '',
                      extra: Sequence[str] = (), video: str = '', frames: str = DEMO,
                      calibration: str = CALIBRATION) -> List[str]:
    """Return the ``mv3dpose_image_publisher`` command of Panoptic camera ``cam``."""
    source = [video] if video else [os.path.join(frames, cam), '--preload']
    cmd = ['mv3dpose_image_publisher', *source, '--camera', cam, '--rate', f'{rate:g}',
           '--loop', '--calibration', calibration, *extra]
    return cmd + (['--compressed', compressed] if compressed else [])


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
    from mv3dpose_ros.core.calibration import load_calibration, save_rig_yaml
    from mv3dpose_ros.core.camera import Camera
    from mv3dpose_ros.pose2d.estimator import open_estimator
    from mv3dpose_ros.pose2d.models import resolve_model_path
    folder = os.path.join(tempfile.gettempdir(), 'bench_rig_portrait')
    rig = load_calibration(CALIBRATION, cameras=cams)
    estimator = open_estimator(resolve_model_path('yolo11n-pose', '384x640'), threads=1)
    out_w, out_h = 1080, 1920
    portrait = {}
    for cam, c in rig.items():
        crop_w = int(round(c.height * out_w / out_h))
        images = {name: cv2.imread(os.path.join(DEMO, cam, name))
                  for name in sorted(os.listdir(os.path.join(DEMO, cam)))}
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
    save_rig_yaml(portrait, path, comment='Panoptic cameras as portrait cameras (bench_rig.py)')
    return folder, path


def make_videos(cams: Sequence[str], rate: float, hold: float,
                frames: str = DEMO) -> Dict[str, str]:
    """Write each camera's Panoptic frames as an MPEG-4 video, each shown ``hold`` s."""
    import cv2
    kind = '_portrait' if frames != DEMO else ''
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
        print(f'bench_rig: wrote {path} ({repeat} frames per time point)', flush=True)
    return out


def stop(procs: Sequence[subprocess.Popen], timeout: float = 20.0) -> None:
    """SIGINT every process (its group), then kill what is left after ``timeout``."""
    for p in procs:
        if p.poll() is None:
            try:
                os.killpg(p.pid, signal.SIGINT)
            except ProcessLookupError:
                pass
    deadline = time.monotonic() + timeout
    for p in procs:
        try:
            p.wait(timeout=max(0.1, deadline - time.monotonic()))
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait()


def published_counts(logs: Dict[str, str]) -> Dict[str, str]:
    """Read 'published N frames[, skipped M instants]' from each publisher log."""
    import re
    out = {}
    for cam, path in logs.items():
        with open(path, encoding='utf-8', errors='replace') as f:
            hits = re.findall(r'published (\d+) frames(?:, skipped (\d+) instants)?', f.read())
        if hits:
            n, skipped = hits[-1]
            out[cam] = n + (f' (skipped {skipped} instants, CPU)' if skipped else '')
    return out


def main() -> int:
    """Run the rig and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--cameras', type=int, default=4)
    parser.add_argument('--rate', type=float, default=10.0)
    parser.add_argument('--hold', type=float, default=0.0,
                        help='show each Panoptic time point this long [s] (a still scene per '
                             'image, so tracks can persist); 0: a new one every instant')
    parser.add_argument('--duration', type=float, default=60.0)
    parser.add_argument('--warmup', type=float, default=10.0,
                        help='seconds after every camera answered before measuring')
    parser.add_argument('--compressed', choices=('jpeg', 'png'), default='')
    parser.add_argument('--max-wait-s', type=float, default=None,
                        help='sync.max_wait_s to judge skew (default: config/fusion.yaml)')
    parser.add_argument('--people', type=int, default=3)
    parser.add_argument('--fusion-param', action='append', default=[], metavar='NAME:=VALUE',
                        help='passed to mv3dpose_bringup (e.g. sync.max_wait_s:=0.5)')
    parser.add_argument('--pose2d-param', action='append', default=[], metavar='NAME:=VALUE',
                        help='passed to mv3dpose_bringup (e.g. inference_rate_hz:=2)')
    parser.add_argument('--logs', default='', help='folder for the process logs')
    parser.add_argument('--video', action='store_true',
                        help='replay the frames as one MPEG-4 video per camera (each time '
                             'point --hold s long) instead of image folders')
    parser.add_argument('--portrait', action='store_true',
                        help="portrait cameras: each frame's 9:16 window around the people, "
                             'scaled to 1080x1920, with its calibration')
    args = parser.parse_args()
    if not os.path.isdir(DEMO):
        print(f'bench_rig: skipped: no Panoptic frames at {DEMO}')
        return 0
    cams = CAMERAS[:args.cameras]
    max_wait = args.max_wait_s
    for item in args.fusion_param:
        if item.startswith('sync.max_wait_s:='):
            max_wait = float(item.split(':=', 1)[1])
    if max_wait is None:
        import yaml
        with open(os.path.join(ROOT, 'config', 'fusion.yaml'), encoding='utf-8') as f:
            doc = yaml.safe_load(f)
        max_wait = next((float(s['ros__parameters']['sync']['max_wait_s'])
                         for s in doc.values() if 'sync' in s.get('ros__parameters', {})), 0.1)
    frames, calibration = portrait_rig(cams) if args.portrait else (DEMO, CALIBRATION)
    videos = make_videos(cams, args.rate, args.hold, frames) if args.video else {}
    logdir = args.logs or tempfile.mkdtemp(prefix='bench_rig_')
    os.makedirs(logdir, exist_ok=True)
    procs, logs = [], {}
    probe = Probe(cams)
    t_start = time.time_ns()

    def launch(cmd: List[str], name: str) -> subprocess.Popen:
        log = open(os.path.join(logdir, f'{name}.log'), 'w')
        return subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, cwd=ROOT,
                                start_new_session=True)

    try:
        over = [a for p in args.fusion_param for a in ('--fusion-param', p)]
        over += [a for p in args.pose2d_param for a in ('--pose2d-param', p)]
        procs.append(launch(['mv3dpose_bringup', '--rig', calibration, '--cameras', *cams,
                             *over], 'bringup'))
        for cam in cams:
            logs[cam] = os.path.join(logdir, f'publisher_{cam}.log')
            hold = ['--hold', f'{args.hold:g}'] if args.hold and not videos else []
            procs.append(launch(publisher_command(cam, args.rate, args.compressed,
                                                  ['--wait-for-subscribers', '1', *hold],
                                                  videos.get(cam, ''), frames, calibration),
                                f'publisher_{cam}'))
        deadline = time.monotonic() + 120
        while probe.cameras_answering() < len(cams) and time.monotonic() < deadline:
            if procs[0].poll() is not None:
                stop(procs[1:])
                probe.close()
                raise SystemExit(f'bringup exited with {procs[0].returncode}; see {logdir}')
            time.sleep(0.2)
        t_ready = time.time_ns()
        time.sleep(args.warmup + args.duration + 2.0)
        t_end = time.time_ns() - 2 * NS
        first = probe.first_confirmed(args.people, t_start)
        share = probe.confirmed_share(args.people, t_ready + int(args.warmup * NS), t_end)
        names = sorted(os.listdir(os.path.join(DEMO, cams[0])))
        by_point = probe.confirmed_by_time_point(
            t_ready + int(args.warmup * NS), t_end, int(args.hold * NS), len(names)
        ) if args.hold else {}
    finally:
        stop(procs[1:])
        stop(procs[:1])
        time.sleep(0.5)
    res = analyse(probe, t_ready + int(args.warmup * NS), t_end, max_wait)
    published = published_counts(logs)
    probe.close()
    size = '1080x1920' if args.portrait else '1920x1080'
    print(f'{len(cams)} cameras x {size} {args.compressed or "bgr8"} at {args.rate:g} Hz, '
          f'{args.duration:g} s measured after {args.warmup:g} s warm-up; bringup '
          f'{" ".join(args.fusion_param + args.pose2d_param) or "defaults"}; '
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
    return 0


if __name__ == '__main__':
    sys.exit(main())
