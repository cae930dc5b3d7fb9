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
fusion_node as its own process, fed at 60 fps without pacing to its output: it keeps up.

Detections of a simulated 4-camera rig are published at the real 60 fps rate on wall-clock
stamps (as a recorded bag played at rate 1), with the shipped config/fusion.yaml defaults;
nothing waits for the node's output. At least 98 % of the published time points must come out
as track sets.
"""

import os
import time

from diagnostic_msgs.msg import DiagnosticArray
from mv3dpose_msgs.msg import Person2DArray, TrackedSkeletonArray
from mv3dpose_ros.core.geometry.calibration import save_rig_yaml
from mv3dpose_ros.ros.messages import ns_to_stamp, numpy_to_person2d_array
from mv3dpose_ros.ros.qos import reliable_qos
from mv3dpose_ros.sim import make_scene
from mv3dpose_ros.testing.probe import all_matched, diagnostics_text, Probe
from mv3dpose_ros.testing.processes import NodeProcess
import pytest
from rclpy.serialization import serialize_message
from std_msgs.msg import Header

pytestmark = [pytest.mark.ros]

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FPS = 60.0
NS = 1_000_000_000


def test_sixty_fps_unpaced_default_parameters_emit_98_percent(tmp_path, ros_context):
    frames = 360
    scene = make_scene(num_cameras=4, num_people=3, num_frames=frames, fps=FPS, seed=5)
    rig = str(tmp_path / 'rig.yaml')
    save_rig_yaml(scene.cameras, rig)
    proc = NodeProcess(['fusion_node', '--ros-args', '--params-file',
                        os.path.join(ROOT, 'config', 'fusion.yaml'), '-p', f'rig_config:={rig}'],
                       tmp_path / 'fusion_node.log')
    probe = Probe('player', context=ros_context)
    executor = probe.executor
    diags = probe.subscribe(DiagnosticArray, '/diagnostics', reliable_qos(50))
    received = probe.subscribe(TrackedSkeletonArray, '/fusion_node/tracks', reliable_qos(1000),
                               raw=True)
    pubs = probe.camera_publishers(Person2DArray, scene.cameras)
    cams = list(scene.cameras)
    try:
        probe.spin_until(lambda: all_matched(pubs.values()) and
                         probe.node.count_publishers('/fusion_node/tracks'), 30, [proc], 0.05)
        time.sleep(1.0)               # let discovery settle both ways
        # The "bag": every message serialised beforehand, stamped on the wall clock it will
        # be played at.
        lead_s = 3.0
        t0 = time.time_ns() + int(lead_s * NS)
        bag = [{c: serialize_message(numpy_to_person2d_array(
            scene.views[f][c], Header(stamp=ns_to_stamp(t0 + int(f * NS / FPS)), frame_id=c),
            c, scene.cameras[c].width, scene.cameras[c].height, scene.layout)) for c in cams}
            for f in range(frames)]
        start = time.monotonic() + lead_s - (time.time_ns() - t0 + int(lead_s * NS)) / NS
        for f in range(frames):
            data = bag[f]
            while time.monotonic() < start + f / FPS:     # the player's 60 fps clock
                executor.spin_once(timeout_sec=max(0.0, start + f / FPS - time.monotonic()))
            for c in cams:
                pubs[c].publish(data[c])
        end = time.monotonic() + 5.0
        while time.monotonic() < end and len(received) < frames:
            executor.spin_once(timeout_sec=0.05)
    finally:
        code = proc.interrupt(10)
        probe.close()
    text = proc.log()
    print(f'{len(received)} track sets for {frames} published time points '
          f'({100 * len(received) / frames:.1f} %)')
    assert code == 0, text
    warnings = '\n'.join(line for line in text.splitlines() if 'INFO' not in line)
    warnings += '\n' + diagnostics_text(diags)
    assert len(received) >= 0.98 * frames, warnings[-3000:]
