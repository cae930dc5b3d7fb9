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

"""``mv3dpose detect``: real Panoptic images and a video -> OpenPose JSON -> ``mv3dpose track``."""

import json
import os
import shutil
import subprocess
import sys

import cv2
from mv3dpose_ros.io.openpose import read_openpose_file
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CAMS = ('00_03', '00_06', '00_12')


def mv3dpose(*args, timeout=300):
    return subprocess.run([sys.executable, '-m', 'mv3dpose_ros.cli', *args], cwd=ROOT,
                          capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope='module')
def model():
    from mv3dpose_ros.pose2d.models import ModelNotFound, resolve_model_path
    try:
        return resolve_model_path('yolo11n-pose')
    except ModelNotFound as exc:
        pytest.skip(str(exc))


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
