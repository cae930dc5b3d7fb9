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
The DDS harness of the fusion_node tests: a node and a probe in one context, simulated streams.

Scenes come from ``mv3dpose_ros.sim`` (deterministic by seed). ``Harness`` runs a
``FusionNode`` and a probe node that publishes per-camera ``Person2DArray`` and records
``~/tracks``, ``/diagnostics``, the skeleton info and the markers; ``stream`` yields a scene's
messages with jitter, drops and skips. Header stamps sit a few seconds in the past of the wall
clock, as a live rig's would, so the far-future check stays meaningful. The fixtures ``scene``,
``rig_path`` and ``harness_factory`` reach the tests as a plugin (``pytest_plugins``).
"""

import random
import time

from diagnostic_msgs.msg import DiagnosticArray
from mv3dpose_msgs.msg import Person2DArray, SkeletonInfo, TrackedSkeletonArray
from mv3dpose_ros.core.geometry.calibration import save_rig_yaml
from mv3dpose_ros.core.types import TrackState
from mv3dpose_ros.ros.messages import msg_to_tracks, ns_to_stamp, numpy_to_person2d_array
from mv3dpose_ros.ros.messages import stamp_to_ns
from mv3dpose_ros.ros.qos import latched_qos, reliable_qos
from mv3dpose_ros.sim import make_scene
from mv3dpose_ros.testing.spin import spin_for, spin_until
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from std_msgs.msg import Header
from visualization_msgs.msg import MarkerArray

FPS = 30.0
NS = 1_000_000_000


@pytest.fixture(scope='module')
def scene():
    """4 cameras, 3 people walking, 3 s at 30 Hz with the default detector noise."""
    return make_scene(num_cameras=4, num_people=3, num_frames=90, fps=FPS, seed=7)


@pytest.fixture(scope='module')
def rig_path(scene, tmp_path_factory):
    path = str(tmp_path_factory.mktemp('rig') / 'rig.yaml')
    save_rig_yaml(scene.cameras, path)
    return path


def base_ns(num_frames: int) -> int:
    """Stamp of frame 0: the sequence ends ~0.5 s before now (stamps in the recent past)."""
    return time.time_ns() - int((num_frames / FPS + 0.5) * NS)


def person_msg(scene, cam, poses, stamp_ns):
    c = scene.cameras[cam]
    header = Header(stamp=ns_to_stamp(stamp_ns), frame_id=f'{cam}_optical_frame')
    return numpy_to_person2d_array(poses, header, cam, c.width, c.height, scene.layout)


class Harness:
    """A FusionNode and a probe node (publishers per camera, output subscribers)."""

    def __init__(self, scene, rig_path, markers=False, **params):
        from mv3dpose_ros.nodes.fusion.node import FusionNode
        self.scene = scene
        self.ctx = rclpy.Context()
        rclpy.init(context=self.ctx)
        # sync.max_wait_s 0.5: the probe publishes in bursts from the thread that also spins
        # the node, so on a loaded machine a frame's messages can reach the node more than
        # the default 0.1 s apart (the arrival-time behaviour itself is in test_sync.py).
        overrides = {'rig_config': rig_path, 'input_topic': '/{camera}/persons_2d',
                     'diagnostics.period_s': 0.2, 'log_throttle_s': 0.0,
                     'sync.max_wait_s': 0.5}
        overrides.update(params)
        self.node = FusionNode(context=self.ctx, parameter_overrides=[
            Parameter(k, value=v) for k, v in overrides.items()])
        self.probe = rclpy.create_node('probe', context=self.ctx)
        self.pubs = {c: self.probe.create_publisher(Person2DArray, f'/{c}/persons_2d',
                                                    reliable_qos(100))
                     for c in scene.cameras}
        self.tracks, self.diags, self.infos = [], [], []
        self.probe.create_subscription(TrackedSkeletonArray, '/fusion_node/tracks',
                                       self.tracks.append, reliable_qos(500))
        self.probe.create_subscription(DiagnosticArray, '/diagnostics', self.diags.append,
                                       reliable_qos(50))
        self.probe.create_subscription(SkeletonInfo, '/fusion_node/skeleton_info',
                                       self.infos.append, latched_qos())
        self.markers = []
        if markers:
            self.probe.create_subscription(MarkerArray, '/fusion_node/markers',
                                           self.markers.append, reliable_qos(500))
        self.executor = SingleThreadedExecutor(context=self.ctx)
        self.executor.add_node(self.node)
        self.executor.add_node(self.probe)
        assert self.spin_until(lambda: all(p.get_subscription_count() for p in
                                           self.pubs.values())), 'fusion_node never matched'

    def spin_until(self, predicate, timeout=10.0):
        return spin_until(self.executor, predicate, timeout)

    def spin_for(self, seconds):
        spin_for(self.executor, seconds)

    def publish(self, cam, msg, spin=2):
        self.pubs[cam].publish(msg)
        for _ in range(spin):
            self.executor.spin_once(timeout_sec=0.0)

    def wait_sets(self, count, timeout=10.0):
        """Wait until the node emitted ``count`` sets and the probe received them all."""
        return self.spin_until(lambda: self.node.live.counts['sets'] >= count and
                               len(self.tracks) >= self.node.live.counts['sets'], timeout)

    def latest_status(self, suffix):
        for arr in reversed(self.diags):
            for s in arr.status:
                if s.name.endswith(suffix):
                    return s
        return None

    def close(self):
        self.executor.shutdown()
        self.node.destroy_node()
        self.probe.destroy_node()
        rclpy.shutdown(context=self.ctx)


@pytest.fixture
def harness_factory(scene, rig_path):
    made = []

    def make(markers=False, **params):
        h = Harness(scene, rig_path, markers, **params)
        made.append(h)
        return h

    yield make
    for h in made:
        h.close()


def published_frames(tracks_msgs):
    """Return {stamp_ns: [Track]} of the confirmed/coasting tracks of each output message."""
    out = {}
    for m in tracks_msgs:
        out[stamp_to_ns(m.header.stamp)] = [t for t in msg_to_tracks(m)
                                            if t.state in (TrackState.CONFIRMED,
                                                           TrackState.COASTING)]
    return out


def stream(scene, t0, frames, drop=0.0, jitter_ns=0, seed=0, skip=None):
    """Yield (cam, msg, frame) per camera per frame with per-camera jitter and drops."""
    rng = random.Random(seed)
    for f in frames:
        for cam, poses in scene.views[f].items():
            if rng.random() < drop or (skip and skip(cam, f)):
                continue
            stamp = t0 + int(round(f * NS / FPS)) + rng.randint(-jitter_ns, jitter_ns)
            yield cam, person_msg(scene, cam, poses, stamp), f
