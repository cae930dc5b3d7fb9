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

"""``mv3dpose detect``: real Panoptic images and Pose2Sim videos -> OpenPose JSON -> track."""

import json
import os
import shutil
import subprocess
import sys

import cv2
from mv3dpose_ros.io.openpose import read_openpose_file
import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CAMS = ('00_03', '00_06', '00_12')


def mv3dpose(*args, timeout=300):
    return subprocess.run([sys.executable, '-m', 'mv3dpose_ros.cli', *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)


@pytest.mark.slow
def test_detect_then_track_finds_the_three_people(shared_data, model, tmp_path):
    demo = os.path.join(shared_data, 'panoptic_demo')
    calib = os.path.join(demo, 'camera_parameters.json')
    out = tmp_path / 'poses'
    res = mv3dpose('detect', '--images', demo, '-c', calib, '-o', str(out), '--cameras', *CAMS,
                   '--no-progress')
    assert res.returncode == 0, res.stderr
    assert f'mv3dpose track --calibration {calib} --poses {out} --layout coco17' in res.stdout
    for cam in CAMS:
        files = sorted(os.listdir(out / cam))
        assert files == [f'{cam}_{n:012d}_keypoints.json'
                         for n in (4500, 5514, 6859, 9348, 13007)]
        people = [read_openpose_file(str(out / cam / f)) for f in files]
        assert all(p.shape[1:] == (17, 3) for p in people)
        assert sum(len(p) >= 2 for p in people) >= 4          # 3 people in most views
    tracks = tmp_path / 'tracks.jsonl'
    res = mv3dpose('track', '--calibration', calib, '--poses', str(out), '--layout', 'coco17',
                   '--fps', '30', '--cameras', *CAMS, '--smooth', 'none', '-o', str(tracks),
                   '--no-progress')
    assert res.returncode == 0, res.stderr
    frames = [json.loads(line) for line in tracks.read_text().splitlines()]
    assert [f['frame'] for f in frames] == [4500, 5514, 6859, 9348, 13007]
    people = [sum(t['state'] != 'deleted' for t in f['tracks']) for f in frames]
    assert sum(n == 3 for n in people) >= 3, people


@pytest.mark.slow
def test_detect_reads_videos_and_reports_bad_images(shared_data, model, tmp_path):
    src = os.path.join(shared_data, 'panoptic_demo', '00_03')
    images = tmp_path / 'images'
    (images / 'left').mkdir(parents=True)
    writer = cv2.VideoWriter(str(images / 'right.avi'), cv2.VideoWriter_fourcc(*'MJPG'), 25.0,
                             (960, 540))
    for k, name in enumerate(sorted(os.listdir(src))[:3]):
        frame = cv2.resize(cv2.imread(os.path.join(src, name)), (960, 540))
        writer.write(frame)
        shutil.copy(os.path.join(src, name), images / 'left' / f'left_{k + 7}.jpg')
    writer.release()
    (images / 'left' / 'left_10.jpg').write_bytes(b'not a jpeg')
    out = tmp_path / 'poses'
    res = mv3dpose('detect', '--images', str(images), '-o', str(out), '--no-progress')
    assert res.returncode == 0, res.stderr
    assert 'skipped' in res.stderr and 'left_10.jpg: cannot decode the image' in res.stderr
    assert '1 unreadable image(s) skipped' in res.stdout and '--fps 25 ' in res.stdout
    assert sorted(os.listdir(out / 'left')) == [f'left_{k:012d}_keypoints.json' for k in (7, 8, 9)]
    assert sorted(os.listdir(out / 'right')) == [f'right_{k:012d}_keypoints.json'
                                                 for k in (0, 1, 2)]
    found = [len(read_openpose_file(str(out / 'right' / f))) for f in os.listdir(out / 'right')]
    assert min(found) >= 2


def test_detect_errors_name_the_problem(tmp_path):
    res = mv3dpose('detect', '--images', str(tmp_path / 'nope'), '-o', str(tmp_path / 'o'))
    assert res.returncode == 2 and 'nope: input folder does not exist' in res.stderr
    (tmp_path / 'cam0').mkdir()
    res = mv3dpose('detect', '--images', str(tmp_path), '-o', str(tmp_path / 'o'),
                   '--model-path', str(tmp_path / 'missing.onnx'))
    assert res.returncode == 2 and 'model file not found' in res.stderr


POSE2SIM_CALIB = ('pose2sim_multiperson', 'Calib_qualisys.toml')    # cam_01..cam_04, 1088x1920


def _clip(video, path, size=None, frames=2):
    """Write the first frames of ``video`` (resized to ``size``) as an MJPG video at ``path``."""
    cap = cv2.VideoCapture(video)
    images = [cap.read()[1] for _ in range(frames)]
    cap.release()
    images = [cv2.resize(im, size, interpolation=cv2.INTER_AREA) if size else im
              for im in images]
    h, w = images[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*'MJPG'), 10.0, (w, h))
    for im in images:
        writer.write(im)
    writer.release()
    return images


def _keypoints(folder):
    return [read_openpose_file(str(folder / f)) for f in sorted(os.listdir(folder))]


@pytest.mark.slow
def test_detect_matches_pose2sim_videos_and_maps_image_sizes(shared_data, model, tmp_path):
    # Pose2Sim's videos are cam01.mp4.. for cameras cam_01.., 1080x1920 for a 1088x1920
    # calibration (a codec's padding): two frames of cam01 as they are (cropped, keypoints
    # kept), cam02 resized to 544x960 (half the calibration: scaled) and cam03 as a folder of
    # landscape images (a mismatch: warned, kept in image pixels); cam04 has nothing.
    videos = os.path.join(shared_data, 'pose2sim_singleperson', 'videos')
    calib = os.path.join(shared_data, *POSE2SIM_CALIB)
    src = tmp_path / 'videos'
    (src / 'cam03').mkdir(parents=True)
    _clip(os.path.join(videos, 'cam01.mp4'), src / 'cam01.avi')
    _clip(os.path.join(videos, 'cam02.mp4'), src / 'cam02.avi', size=(544, 960))
    for k, im in enumerate(_clip(os.path.join(videos, 'cam03.mp4'), tmp_path / 'tmp.avi')):
        cv2.imwrite(str(src / 'cam03' / f'{k:04d}.png'), cv2.resize(im, (960, 544)))
    out = tmp_path / 'calibrated'
    res = mv3dpose('detect', '--images', str(src), '-c', calib, '-o', str(out), '--no-progress')
    assert res.returncode == 0, res.stderr
    assert sorted(os.listdir(out)) == ['cam_01', 'cam_02', 'cam_03']      # calibrated names
    assert sorted(os.listdir(out / 'cam_01')) == [f'cam_01_{k:012d}_keypoints.json'
                                                  for k in (0, 1)]
    assert '1 calibrated camera(s) have no images: cam_04' in res.stderr
    notes = [line for line in res.stderr.splitlines() if 'note: camera' in line]
    assert len(notes) == 2, res.stderr                                    # one per camera
    assert 'camera cam_01: cropped: image 1080x1920 vs calibration 1088x1920' in notes[0]
    assert 'keypoints unchanged' in notes[0] and 'right/bottom' in notes[0]
    assert 'camera cam_02: scaled: image 544x960 vs calibration 1088x1920' in notes[1]
    assert 'scaled by 2 x 2' in notes[1]
    assert 'warning: camera cam_03: images are 960x544 but the calibration says 1088x1920' \
        in res.stderr and 'tracking will be wrong unless the calibration is fixed' in res.stderr
    assert 'rotated or wrong camera' in res.stderr
    # The same inputs without a calibration: raw image pixels, folders named as the files.
    raw = tmp_path / 'raw'
    res = mv3dpose('detect', '--images', str(src), '-o', str(raw), '--no-progress')
    assert res.returncode == 0, res.stderr
    assert sorted(os.listdir(raw)) == ['cam01', 'cam02', 'cam03']
    assert 'note:' not in res.stderr and 'warning:' not in res.stderr
    for cam, name in (('cam_01', 'cam01'), ('cam_03', 'cam03')):            # kept as they are
        pairs = list(zip(_keypoints(out / cam), _keypoints(raw / name)))
        assert len(pairs) == 2 and all(np.array_equal(a, b) for a, b in pairs)
    assert all(len(p) >= 1 for p in _keypoints(raw / 'cam01'))
    for mapped, image in zip(_keypoints(out / 'cam_02'), _keypoints(raw / 'cam02')):
        assert len(image) >= 1 and mapped.shape == image.shape
        seen = image[..., 2] > 0
        want = image.copy()
        want[..., :2][seen] = (image[..., :2][seen] + 0.5) * 2.0 - 0.5   # pixel centres
        np.testing.assert_allclose(mapped, want, atol=2e-3)
        assert mapped[seen][:, 1].max() > 960                      # in the 1088x1920 frame


def test_detect_matches_cameras_loosely_and_names_ambiguities(shared_data, tmp_path):
    calib = os.path.join(shared_data, *POSE2SIM_CALIB)
    (tmp_path / 'cam01').mkdir()
    (tmp_path / 'cam01.mp4').write_bytes(b'')
    res = mv3dpose('detect', '--images', str(tmp_path), '-c', calib, '-o', str(tmp_path / 'o'),
                   '--model-path', str(tmp_path / 'missing.onnx'))
    assert res.returncode == 2
    assert ("camera 'cam_01' matches several folders or videos in "
            f'{tmp_path}: cam01, cam01.mp4') in res.stderr, res.stderr
    (tmp_path / 'cam01.mp4').unlink()
    (tmp_path / 'Cam_1').mkdir()
    res = mv3dpose('detect', '--images', str(tmp_path), '-c', calib, '-o', str(tmp_path / 'o'),
                   '--model-path', str(tmp_path / 'missing.onnx'))
    assert res.returncode == 2 and 'Cam_1, cam01' in res.stderr, res.stderr
    (tmp_path / 'Cam_1').rmdir()
    (tmp_path / 'cam2.mkv').write_bytes(b'')           # unambiguous: on to the model
    res = mv3dpose('detect', '--images', str(tmp_path), '-c', calib, '-o', str(tmp_path / 'o'),
                   '--model-path', str(tmp_path / 'missing.onnx'))
    assert res.returncode == 2 and 'model file not found' in res.stderr, res.stderr
