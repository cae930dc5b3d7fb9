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
The probe of a live rig and its analysis: time points inferred, sets emitted, latency, drops.

``RigProbe`` records every camera's ``persons_2d`` (stamp, arrival), every ``~/tracks``
message and ``/diagnostics`` while it spins in a thread of its own. ``bench/bench_pipeline.py``
and ``test/test_live_rig.py`` / ``test/test_live_video_rig.py`` share it, so the test asserts
on the figures the benchmark prints.
"""

import bisect
import os
import re
import time
from typing import Dict, List, Optional, Sequence, Tuple

from diagnostic_msgs.msg import DiagnosticArray
from mv3dpose_msgs.msg import Person2DArray, TrackedSkeletonArray
from mv3dpose_ros.core.types import NS_PER_S
from mv3dpose_ros.ros.names import camera_topic
from mv3dpose_ros.ros.qos import reliable_qos
from mv3dpose_ros.testing.probe import Probe
from mv3dpose_ros.testing.stats import percentile

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PANOPTIC = os.path.join(os.path.dirname(ROOT), 'shared', 'data', 'panoptic_demo')
PANOPTIC_CALIBRATION = os.path.join(PANOPTIC, 'camera_parameters.json')
PANOPTIC_CAMERAS = ('00_03', '00_06', '00_12', '00_13', '00_23')


class RigProbe(Probe):
    """Record persons_2d, tracks and /diagnostics of a running rig (own rclpy context)."""

    def __init__(self, cameras: Sequence[str]) -> None:
        """Subscribe to each camera's ``persons_2d``, the tracks and ``/diagnostics``; spin."""
        super().__init__('rig_probe')
        self.cameras = list(cameras)
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
        self.start_spinning()

    @staticmethod
    def _stamp(header) -> int:
        return header.stamp.sec * NS_PER_S + header.stamp.nanosec

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

    def first_confirmed(self, people: int, since_ns: int) -> Optional[float]:
        """Return seconds from ``since_ns`` to the first tracks with ``people`` confirmed."""
        with self.lock:
            hits = [t for _, t, c, _ in self.tracks if c >= people]
        return (min(hits) - since_ns) / NS_PER_S if hits else None

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

    def wait_cameras(self, timeout: float, processes: Sequence = ()) -> int:
        """Wait until every camera answered (or ``timeout`` s); a dead process raises."""
        from mv3dpose_ros.testing.processes import check_alive
        deadline = time.monotonic() + timeout
        while self.cameras_answering() < len(self.cameras) and time.monotonic() < deadline:
            check_alive(processes)
            time.sleep(0.2)
        return self.cameras_answering()

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


def analyse(probe: RigProbe, start_ns: int, end_ns: int, max_wait_s: float,
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
    skew = {s: (max(c.values()) - min(c.values())) / NS_PER_S for s, c in processable.items()}
    within = [s for s in processable if skew[s] <= max_wait_s]
    first_arrival: Dict[int, int] = {}      # per set stamp (not idle / coasting updates)
    for stamp, arr, _, _ in tracks:
        if point_of(stamp) is not None:
            first_arrival.setdefault(stamp, arr)
    latency = [(arr - stamp) / 1e6 for stamp, arr in first_arrival.items()]

    def pct(part: int, whole: int) -> float:
        return 100.0 * part / whole if whole else float('nan')

    def q(values: List[float], p: float) -> float:
        return percentile(values, p, method='nearest')     # a measured value, not a mean

    skews = list(skew.values())
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


def drop_table(probe: RigProbe, published: Dict[str, str]) -> List[str]:
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
                      extra: Sequence[str] = (), video: str = '', frames: str = PANOPTIC,
                      calibration: str = PANOPTIC_CALIBRATION) -> List[str]:
    """Return the ``mv3dpose_image_publisher`` command of Panoptic camera ``cam``."""
    source = [video] if video else [os.path.join(frames, cam), '--preload']
    cmd = ['mv3dpose_image_publisher', *source, '--camera', cam, '--rate', f'{rate:g}',
           '--loop', '--calibration', calibration, *extra]
    return cmd + (['--compressed', compressed] if compressed else [])


def published_counts(logs: Dict[str, str]) -> Dict[str, str]:
    """Read 'published N frames[, skipped M instants]' from each publisher log."""
    out = {}
    for cam, path in logs.items():
        with open(path, encoding='utf-8', errors='replace') as f:
            hits = re.findall(r'published (\d+) frames(?:, skipped (\d+) instants)?', f.read())
        if hits:
            n, skipped = hits[-1]
            out[cam] = n + (f' (skipped {skipped} instants, CPU)' if skipped else '')
    return out
