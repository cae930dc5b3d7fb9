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

"""Converters: image folders / videos, OpenPose JSON and tracks to and from bags."""

import os
import subprocess
import sys

import cv2
from mv3dpose_ros.core.geometry.calibration import load_calibration, save_rig_yaml
from mv3dpose_ros.core.geometry.camera import Camera
from mv3dpose_ros.core.types import JointState, Track, TrackState
from mv3dpose_ros.io.bag import BagReader
from mv3dpose_ros.io.media import SourceError
from mv3dpose_ros.io.openpose import match_camera_folders, OpenPoseSequence
from mv3dpose_ros.io.tracks_jsonl import read_tracks, TracksWriter
from mv3dpose_ros.ros.bag_convert import bag_to_jsonl, images_to_bag, jsonl_to_bag
from mv3dpose_ros.ros.bag_convert import openpose_to_bag, stamp_ns
from mv3dpose_ros.ros.images import image_from_message
import numpy as np
import pytest

W, H = 64, 48


def _rig(tmp_path, names=('left', 'right')):
    K = np.array([[50.0, 0, W / 2], [0, 50.0, H / 2], [0, 0, 1]])
    cams = {n: Camera.look_at(n, K, [3.0 * (1 if i else -1), -3.0, 1.5], [0, 0, 1], W, H)
            for i, n in enumerate(names)}
    path = tmp_path / 'rig.yaml'
    save_rig_yaml(cams, str(path))
    return str(path), cams


def _image(cam_index, t):
    img = np.zeros((H, W, 3), np.uint8)
    img[..., 0] = cam_index * 40
    img[..., 1] = t * 10
    img[t, :, 2] = 255          # a marker row: which time point this is
    return img


def _image_folders(root, names, frames, ext='.png'):
    for c, name in enumerate(names):
        (root / name).mkdir(parents=True)
        for t in frames:
            cv2.imwrite(str(root / name / f'img_{t:05d}{ext}'), _image(c, frames.index(t)))


def test_image_folders_become_a_synchronised_image_bag(tmp_path):
    rig, cams = _rig(tmp_path)
    frames = [3, 10, 11, 40]               # numbered files, not consecutive
    _image_folders(tmp_path / 'imgs', list(cams), frames)
    out = tmp_path / 'images_bag'
    summary = images_to_bag(str(tmp_path / 'imgs'), rig, str(out), fps=5.0, start_time=100.0,
                            quiet=True)
    assert summary['cameras'] == ['left', 'right'] and summary['time_points'] == 4
    assert summary['frame_numbers'] == frames
    with BagReader(out) as reader:
        topics = reader.topics()
        assert set(topics) == {'/left/image_raw', '/left/camera_info', '/right/image_raw',
                               '/right/camera_info'}
        msgs = list(reader.decoded())
    stamps = [stamp_ns(100.0, i, 5.0) for i in range(4)]
    for c, name in enumerate(cams):
        images = [(t, m) for topic, t, m in msgs if topic == f'/{name}/image_raw']
        infos = [m for topic, _, m in msgs if topic == f'/{name}/camera_info']
        assert [t for t, _ in images] == stamps
        for i, (t, m) in enumerate(images):
            assert m.header.stamp.sec * 10 ** 9 + m.header.stamp.nanosec == t
            assert m.header.frame_id == name and m.encoding == 'bgr8'
            assert np.array_equal(image_from_message(m), _image(c, i))
        assert len(infos) == 4
        assert np.allclose(np.reshape(infos[0].k, (3, 3)), cams[name].K)
        assert (infos[0].width, infos[0].height) == (W, H)


def test_videos_become_an_image_bag(tmp_path):
    rig, cams = _rig(tmp_path)
    (tmp_path / 'vids').mkdir()
    for c, name in enumerate(cams):
        writer = cv2.VideoWriter(str(tmp_path / 'vids' / f'{name}.avi'),
                                 cv2.VideoWriter_fourcc(*'MJPG'), 12.0, (W, H))
        for t in range(5):
            writer.write(_image(c, t))
        writer.release()
    summary = images_to_bag(str(tmp_path / 'vids'), rig, str(tmp_path / 'b'), quiet=True)
    assert summary['time_points'] == 5 and summary['fps'] == pytest.approx(12.0)
    with BagReader(tmp_path / 'b') as reader:
        assert reader.topics()['/left/image_raw'].count == 5
        assert reader.topics()['/right/image_raw'].count == 5


def test_mismatched_camera_names_name_both_sides_and_leave_nothing(tmp_path):
    rig, cams = _rig(tmp_path)
    _image_folders(tmp_path / 'imgs', ['left', 'middle'], [0, 1])
    with pytest.raises(SourceError) as err:
        images_to_bag(str(tmp_path / 'imgs'), rig, str(tmp_path / 'out'), quiet=True)
    text = str(err.value)
    assert 'middle' in text and 'rig.yaml' in text and 'left, right' in text
    assert not (tmp_path / 'out').exists()
    assert not [f for f in os.listdir(tmp_path) if 'partial' in f]


def test_missing_inputs_and_wrong_image_size_are_clear_errors(tmp_path):
    rig, cams = _rig(tmp_path)
    with pytest.raises(SourceError, match='nowhere'):
        images_to_bag(str(tmp_path / 'nowhere'), rig, str(tmp_path / 'out'), quiet=True)
    with pytest.raises(SourceError, match='nocalib.yaml'):
        images_to_bag(str(tmp_path), str(tmp_path / 'nocalib.yaml'), str(tmp_path / 'o'))
    (tmp_path / 'big' / 'left').mkdir(parents=True)
    (tmp_path / 'big' / 'right').mkdir(parents=True)
    for name in ('left', 'right'):
        cv2.imwrite(str(tmp_path / 'big' / name / 'a_0.png'), np.zeros((H, W, 3), np.uint8))
    cv2.imwrite(str(tmp_path / 'big' / 'right' / 'a_1.png'), np.zeros((2 * H, W, 3), np.uint8))
    with pytest.raises(SourceError) as err:
        images_to_bag(str(tmp_path / 'big'), rig, str(tmp_path / 'out'), quiet=True)
    assert 'a_1.png' in str(err.value) and f'{W}x{H}' in str(err.value)
    assert not (tmp_path / 'out').exists()
    assert not [f for f in os.listdir(tmp_path) if 'partial' in f]


def test_cli_error_is_one_line(tmp_path):
    rig, _ = _rig(tmp_path)
    proc = subprocess.run([sys.executable, '-m', 'mv3dpose_ros.cli', 'convert', 'images',
                           str(tmp_path / 'none'), '-c', rig, '-o', str(tmp_path / 'x')],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 1
    assert proc.stderr.startswith('error: ') and 'none' in proc.stderr
    assert 'Traceback' not in proc.stderr


def test_panoptic_demo_images(shared_data, tmp_path):
    root = os.path.join(shared_data, 'panoptic_demo')
    calib = os.path.join(root, 'camera_parameters.json')
    out = tmp_path / 'pan'
    summary = images_to_bag(root, calib, str(out), fps=2.0, cameras=['00_03', '00_23'],
                            quiet=True)
    assert summary['frame_numbers'] == [4500, 5514, 6859, 9348, 13007]
    with BagReader(out) as reader:
        # '00_03' is no valid ROS name token: the camera lives under /cam00_03
        assert sorted(reader.topics()) == ['/cam00_03/camera_info', '/cam00_03/image_raw',
                                           '/cam00_23/camera_info', '/cam00_23/image_raw']
        stamps = {}
        for topic, t, msg in reader.decoded(['/cam00_03/image_raw', '/cam00_23/image_raw']):
            stamps.setdefault(topic, []).append(t)
            assert (msg.width, msg.height) == (1920, 1080)
            assert msg.header.frame_id in ('00_03', '00_23')
    assert stamps['/cam00_03/image_raw'] == stamps['/cam00_23/image_raw']
    assert np.allclose(np.diff(stamps['/cam00_03/image_raw']), 0.5e9)


def test_pose2sim_openpose_to_bag(shared_data, tmp_path):
    from mv3dpose_msgs.msg import Person2DArray
    from mv3dpose_ros.ros.messages import person2d_array_to_numpy
    from rclpy.serialization import deserialize_message
    root = os.path.join(shared_data, 'pose2sim_multiperson')
    calib = os.path.join(root, 'Calib_qualisys.toml')
    out = tmp_path / 'op'
    summary = openpose_to_bag(os.path.join(root, 'pose'), calib, str(out), 'body25b', fps=60.0,
                              start_time=10.0, quiet=True)
    assert summary['cameras'] == ['cam_01', 'cam_02', 'cam_03', 'cam_04']
    assert summary['frames'] == 100 and summary['messages'] == 400
    cams = load_calibration(calib)
    folders, _ = match_camera_folders(os.path.join(root, 'pose'), list(cams))
    seq = OpenPoseSequence(folders, num_joints=25)
    with BagReader(out) as reader:
        got = list(reader.messages(['/cam_02/persons_2d']))
    assert len(got) == 100
    for m in got[::17]:
        msg = deserialize_message(m.data, Person2DArray)
        frame = round((m.timestamp - 10 * 10 ** 9) * 60e-9)
        expected = seq.read(seq.frames[0] + frame)['cam_02']
        assert msg.camera_id == 'cam_02' and msg.layout == 'body25b'
        assert (msg.image_width, msg.image_height) == (cams['cam_02'].width,
                                                       cams['cam_02'].height)
        poses = person2d_array_to_numpy(msg, 25)
        valid = expected[..., 2] > 0
        assert poses.shape == expected.shape
        assert np.allclose(poses[valid], expected[valid], atol=1e-3)


def _track(tid, t, num_joints=17, state=TrackState.CONFIRMED):
    joints = np.arange(num_joints * 3, dtype=float).reshape(-1, 3) * 0.01 + [tid, t * 0.1, 0]
    js = np.full(num_joints, JointState.TRIANGULATED, np.uint8)
    joints[3] = np.nan
    js[3] = JointState.MISSING
    js[4] = JointState.PREDICTED
    return Track(track_id=tid, state=state, joints=joints, confidence=np.linspace(0, 1, 17),
                 joint_state=js, num_views=np.full(num_joints, 2, np.uint8),
                 reprojection_error=np.zeros(num_joints), position=np.array([tid, 0.0, 0.9]),
                 velocity=np.array([0.1, 0.0, 0.0]), first_seen=0.0, last_observed=t,
                 score=0.75)


def test_tracks_jsonl_bag_round_trip(tmp_path):
    src = tmp_path / 'tracks.jsonl'
    with TracksWriter(str(src), 'coco17') as w:
        for f in range(5):
            tracks = [_track(1, f * 0.04), _track(2, f * 0.04)]
            if f == 4:
                tracks.append(_track(9, f * 0.04, state=TrackState.DELETED))
            w.write(100 + f, tracks, 5.0 + f * 0.04)
    bag = tmp_path / 'tracks_bag'
    s = jsonl_to_bag(str(src), str(bag))
    assert s['frames'] == 5 and s['tracks'] == 3
    back = tmp_path / 'back.jsonl'
    s = bag_to_jsonl(str(bag), str(back), fps=25.0, start_time=5.0 - 100 / 25.0)
    assert s['frames'] == 5
    a, b = list(read_tracks(str(src))), list(read_tracks(str(back)))
    assert [f.frame for f in b] == [f.frame for f in a] == list(range(100, 105))
    for fa, fb in zip(a, b):
        assert fb.stamp == pytest.approx(fa.stamp, abs=1e-9) and fb.layout == 'coco17'
        assert [(t.id, t.state) for t in fb.tracks] == [(t.id, t.state) for t in fa.tracks]
        for ta, tb in zip(fa.tracks, fb.tracks):
            assert np.allclose(ta.joints, tb.joints, equal_nan=True, atol=1e-6)
            assert np.array_equal(ta.joint_state, tb.joint_state)
            ok = ta.joint_state != JointState.MISSING   # missing joints carry confidence 0
            assert np.allclose(ta.confidence[ok], tb.confidence[ok], atol=1e-4)
            assert np.all(tb.confidence[~ok] == 0)
    # without fps the frame is the message index
    bag_to_jsonl(str(bag), str(tmp_path / 'idx.jsonl'))
    assert [f.frame for f in read_tracks(str(tmp_path / 'idx.jsonl'))] == list(range(5))


def test_tracks_from_a_bag_without_tracks_is_an_error(tmp_path):
    rig, cams = _rig(tmp_path)
    _image_folders(tmp_path / 'imgs', list(cams), [0])
    images_to_bag(str(tmp_path / 'imgs'), rig, str(tmp_path / 'b'), quiet=True)
    from mv3dpose_ros.io.bag import BagError
    with pytest.raises(BagError, match='TrackedSkeletonArray'):
        bag_to_jsonl(str(tmp_path / 'b'), str(tmp_path / 'out.jsonl'))
    assert not (tmp_path / 'out.jsonl').exists()
    assert not [f for f in os.listdir(tmp_path) if 'partial' in f]
