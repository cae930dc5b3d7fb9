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
fusion_node with inputs whose image size is not the calibration's: cropped or resized views.

A portrait rig calibrated at 1088x1920, as the Pose2Sim rig, whose first two cameras deliver
1080x1920 video (a codec's crop) and whose third runs on a half-size stream: all are used. A
landscape image against the portrait calibration is dropped as 'image_size'. The DDS harness
is ``fusion_harness``'s; every wait is bounded by a timeout.
"""

from fusion_harness import base_ns, Harness    # the DDS harness of fusion_node
from mv3dpose_ros.core.fusion.pipeline import Fusion, FusionConfig
from mv3dpose_ros.core.geometry.calibration import save_rig_yaml
from mv3dpose_ros.core.types import TrackState
from mv3dpose_ros.ros.images import camera_info_from_camera
from mv3dpose_ros.ros.messages import (msg_to_tracks, ns_to_stamp, numpy_to_person2d_array,
                                       stamp_to_ns)
from mv3dpose_ros.ros.qos import sensor_qos
from mv3dpose_ros.sim import make_scene
from mv3dpose_ros.sim.rig import RigConfig
import numpy as np
import pytest
from sensor_msgs.msg import CameraInfo
from std_msgs.msg import Header

pytestmark = [pytest.mark.ros]

FPS = 30.0
NS = 1_000_000_000
FRAMES = 20
CROPPED = ('cam_01', 'cam_02')     # 1080x1920 images of the 1088x1920 calibration
HALF = 'cam_03'                    # 544x960: a resized stream


@pytest.fixture(scope='module')
def portrait(tmp_path_factory):
    """4 portrait cameras at 1088x1920 (the Pose2Sim rig's size), 2 people, 20 frames."""
    rig = RigConfig(width=1088, height=1920, hfov_deg=40.0)
    scene = make_scene(num_cameras=4, num_people=2, num_frames=FRAMES, fps=FPS, seed=11,
                       rig=rig)
    path = str(tmp_path_factory.mktemp('portrait') / 'rig.yaml')
    save_rig_yaml(scene.cameras, path)
    return scene, path


@pytest.fixture
def harness(portrait):
    h = Harness(*portrait, publish_tentative=True)
    yield h
    h.close()


def message(scene, cam, frame, stamp_ns, size=None):
    """Return the Person2DArray of ``cam`` at ``frame``, claiming the image ``size``."""
    poses = np.array(scene.views[frame][cam], dtype=float)
    if size is None and cam in CROPPED:
        size = (1080, 1920)
    if size is None and cam == HALF:
        size = (544, 960)
        seen = poses[..., 2] > 0            # pixel centres of the half-size image
        poses[..., :2][seen] = (poses[..., :2][seen] + 0.5) / 2.0 - 0.5
    c = scene.cameras[cam]
    width, height = size or (c.width, c.height)
    header = Header(stamp=ns_to_stamp(stamp_ns), frame_id=f'{cam}_optical_frame')
    return numpy_to_person2d_array(poses, header, cam, width, height, scene.layout)


def test_cropped_and_resized_inputs_are_used_not_dropped(harness, portrait):
    scene, _ = portrait
    h = harness
    t0 = base_ns(FRAMES)
    for f in range(FRAMES):
        for cam in scene.cameras:
            h.publish(cam, message(scene, cam, f, t0 + int(round(f * NS / FPS))))
    assert h.wait_sets(FRAMES), {c: dict(s.rejected) for c, s in h.node.cams.items()}
    for cam, st in h.node.cams.items():
        assert dict(st.rejected) == {} and st.accepted == FRAMES, cam
        assert st.size_problem == ''
    assert h.node.live.counts['partial_sets'] == 0
    # one warning per camera and size, not per message
    assert h.node.inputs.size_logged == {('cam_01', (1080, 1920), (1088, 1920)),
                                         ('cam_02', (1080, 1920), (1088, 1920)),
                                         ('cam_03', (544, 960), (1088, 1920))}
    # Used exactly as the calibrated-size keypoints would be: the tracks are Fusion.step's on
    # the scene's own views (float32 on the wire), with the half-size camera among the sources.
    fusion = Fusion(scene.cameras, scene.layout, FusionConfig())
    out = {stamp_to_ns(m.header.stamp): msg_to_tracks(m) for m in h.tracks}
    used_half = False
    for f in range(FRAMES):
        stamp = t0 + int(round(f * NS / FPS))
        views = {c: np.asarray(scene.views[f][c], dtype=np.float32).astype(float)
                 for c in scene.cameras}
        expected = fusion.step(views, stamp / NS, stamp)
        got = out[stamp]
        assert [t.track_id for t in got] == [t.track_id for t in expected]
        for a, b in zip(got, expected):
            assert a.state == b.state and a.source_cameras == b.source_cameras
            np.testing.assert_allclose(a.joints, b.joints, atol=1e-4, equal_nan=True)
            used_half |= HALF in b.source_cameras and b.state == TrackState.CONFIRMED
    assert used_half


def test_rotated_image_dropped_naming_the_parameter(harness, portrait):
    scene, _ = portrait
    h = harness
    t0 = base_ns(FRAMES)
    for f in range(4):
        for cam in scene.cameras:
            size = (1920, 1080) if cam == 'cam_04' else None
            h.publish(cam, message(scene, cam, f, t0 + int(round(f * NS / FPS)), size))
    assert h.spin_until(lambda: h.node.cams['cam_04'].rejected['image_size'] == 4, 5.0)
    problem = h.node.cams['cam_04'].size_problem
    assert '1920x1080' in problem and '1088x1920' in problem
    assert 'input_image_size_tolerance_px' in problem
    assert h.wait_sets(3)                     # the other three cameras still make sets
    assert h.node.cams['cam_01'].rejected == {}


def test_camera_info_size_is_what_inputs_are_checked_against(portrait):
    """A CameraInfo of another size than the rig file replaces the camera, size included."""
    scene, path = portrait
    h = Harness(scene, path, publish_tentative=True, intrinsics_source='camera_info')
    try:
        info_pubs = {c: h.probe.create_publisher(CameraInfo, f'/{c}/camera_info',
                                                 sensor_qos('reliable', 1))
                     for c in scene.cameras}
        assert h.spin_until(lambda: all(p.get_subscription_count() for p in info_pubs.values()))
        for cam, camera in scene.cameras.items():
            info = camera_info_from_camera(camera)
            if cam == 'cam_01':
                info.width = 1080             # the driver reports the codec's size
            info_pubs[cam].publish(info)
        assert h.spin_until(lambda: h.node.fusion is not None, 5.0)
        assert (h.node.rig['cam_01'].width, h.node.rig['cam_02'].width) == (1080, 1088)
        t0 = base_ns(FRAMES)
        for f in range(3):
            for cam in scene.cameras:
                size = (1080, 1920) if cam in CROPPED else (1088, 1920)
                h.publish(cam, message(scene, cam, f, t0 + int(round(f * NS / FPS)), size))
        assert h.wait_sets(3)
        assert all(st.rejected == {} for st in h.node.cams.values())
        # cam_01's images have its CameraInfo's size: nothing to map; cam_02's are a crop of it
        assert h.node.inputs.size_logged == {('cam_02', (1080, 1920), (1088, 1920))}
    finally:
        h.close()
