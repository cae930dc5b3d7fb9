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
Pre/post-processing of the pose adapters and their execution providers, on crafted ONNX models.

The models are written by ``onnx_min`` (protobuf by hand; the ``onnx`` package is not in the
venv) and return fixed tensors, so every expected number below follows from the letterbox
geometry alone: no real network is needed. Model files (fetch, checksums, int8) are
``test_pose2d_model_files``'s; images as the nodes receive them ``test_image_inputs``'s.
"""

from mv3dpose_ros.pose2d import models
from mv3dpose_ros.pose2d.estimator import ModelError, open_estimator
from mv3dpose_ros.pose2d.ops import Letterbox, nms
import numpy as np
from onnx_min import make_constant_model
from pose2d_models import person_keypoints, yolo_case_model
import pytest

H, W = 1080, 1920          # original image (Panoptic HD size)
IN = (640, 640)


def _write(tmp_path, name, data):
    path = tmp_path / name
    path.write_bytes(data)
    return str(path)


@pytest.fixture
def yolo_case(tmp_path):
    """Return a YOLO-pose ONNX whose output holds two people, a duplicate, a low score."""
    return yolo_case_model(tmp_path)


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
    kpts, _ = person_keypoints(rng, (900, 540), 200)
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
