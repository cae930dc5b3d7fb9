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
fusion_node's calibration watch over real DDS: a turned camera in /diagnostics, ~/rig, save_rig.

A probe publishes five simulated cameras; from frame 120 on one camera's keypoints move as a
3 degree turn of that camera moves them. The node must say so per camera in ``/diagnostics``,
correct the camera (``fusion.calibration_watch`` correct, the default), publish the corrected
rig on the latched ``~/rig`` and write it to ``save_rig``. Every wait is bounded by a timeout.
"""

from diagnostic_msgs.msg import DiagnosticStatus
from fusion_harness import base_ns, FPS, NS, person_msg
from mv3dpose_ros.core.geometry.calibration import load_calibration
from mv3dpose_ros.core.geometry.camera import turn_keypoints, turned
from mv3dpose_ros.core.selfcal.watch import rotation_angle_deg
from mv3dpose_ros.ros.qos import latched_qos
from mv3dpose_ros.sim import make_scene
import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from std_msgs.msg import String
import yaml

pytestmark = [pytest.mark.ros]
pytest_plugins = ['fusion_harness']

BUMPED, BUMP_AT = 'cam_02', 120
TURN = Rotation.from_rotvec(np.radians(3.0) * np.array([0.6, 0.8, 0.0])).as_matrix()


@pytest.fixture(scope='module')
def scene():
    """Five cameras, 3 people, 10 s at 30 Hz (the watch needs a few seconds of baseline)."""
    return make_scene(num_cameras=5, num_people=3, num_frames=300, fps=FPS, seed=4)


def test_a_turned_camera_is_reported_corrected_published_and_saved(harness_factory, scene,
                                                                   tmp_path):
    saved = tmp_path / 'rig_in_use.yaml'
    h = harness_factory(save_rig=str(saved))
    rigs = []
    h.probe.create_subscription(String, '/fusion_node/rig', rigs.append, latched_qos())
    assert h.spin_until(lambda: rigs, 5.0), 'no ~/rig at start'
    assert saved.is_file() and 'the rig in use at start' in rigs[0].data
    t0 = base_ns(scene.num_frames)
    for f in range(scene.num_frames):
        for cam, poses in scene.views[f].items():
            if cam == BUMPED and f >= BUMP_AT and len(poses):
                poses = poses.copy()
                poses[..., :2] = turn_keypoints(scene.cameras[cam], poses[..., :2], TURN)
            h.publish(cam, person_msg(scene, cam, poses, t0 + int(round(f * NS / FPS))))
    assert h.spin_until(lambda: len(rigs) >= 2, 20.0), 'the correction never came'
    assert 'corrected by the calibration watch' in rigs[-1].data
    truth = turned(scene.cameras[BUMPED], TURN)
    published = yaml.safe_load(rigs[-1].data)['cameras']
    assert set(published) == set(scene.cameras)
    for rig in (load_calibration(str(saved)), h.node.live.cameras):
        assert rotation_angle_deg(rig[BUMPED].R @ truth.R.T) < 0.3
        for cam in scene.cameras:
            if cam != BUMPED:
                assert np.allclose(rig[cam].R, scene.cameras[cam].R, atol=1e-6)
    h.spin_for(0.5)
    named = [s for arr in h.diags for s in arr.status
             if s.name.endswith(f'{BUMPED} calibration watch')]
    assert named and any(s.level != DiagnosticStatus.OK for s in named), \
        'never WARN/ERROR in /diagnostics'
    last = {kv.key: kv.value for kv in named[-1].values}
    assert last['corrections'] == '1' and last['calibration'] == 'OK'
    others = [s for arr in h.diags for s in arr.status
              if s.name.endswith('calibration watch') and s.hardware_id != BUMPED]
    assert others and all(s.level == DiagnosticStatus.OK for s in others)
