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
Crafted pose models and images for the pose2d tests: no download, known detections.

``crafted_model`` writes a YOLO-pose ONNX whose "network" always returns the same two people,
so the expected keypoints follow from the letterbox alone; ``yolo_case_model`` one laid out on
an HD image with a duplicate and a low-score box besides; ``fake_cache`` a model cache of such
files at the input sizes and precisions a test needs; ``image_folder`` random frames.
"""

import hashlib
import json

import cv2
from mv3dpose_ros.pose2d import models
from mv3dpose_ros.pose2d.ops import Letterbox
import numpy as np
from onnx_min import make_constant_model

W, H = 320, 240
HD = (1080, 1920)          # the original image of ``yolo_case_model`` (Panoptic HD size)


def crafted_model(tmp_path):
    """Write a YOLO-pose ONNX that always 'sees' two people; return path and expectations."""
    lb = Letterbox.fit((H, W), (640, 640))
    rng = np.random.default_rng(5)
    out = np.zeros((1, 56, 8400), np.float32)
    expected = []
    for col, (cx, cy), score in ((10, (100, 120), 0.9), (20, (230, 110), 0.6)):
        kpts = np.array([cx, cy]) + rng.uniform(-30, 30, size=(17, 2))
        conf = rng.uniform(0.4, 1.0, 17)
        x0, y0 = lb.to_input(kpts.min(0) - 5)
        x1, y1 = lb.to_input(kpts.max(0) + 5)
        k_in = lb.to_input(kpts)
        out[0, :5, col] = [(x0 + x1) / 2, (y0 + y1) / 2, x1 - x0, y1 - y0, score]
        out[0, 5:, col] = np.concatenate([k_in, conf[:, None]], 1).reshape(-1)
        expected.append((kpts, conf, score))
    path = tmp_path / 'crafted_pose.onnx'
    path.write_bytes(make_constant_model([('images', np.float32, [1, 3, 640, 640])],
                                         {'output0': out}, {'task': 'pose'}))
    return str(path), expected


def image_folder(tmp_path, count=3):
    """Write ``count`` random W x H frames into a folder; return its path."""
    folder = tmp_path / 'frames'
    folder.mkdir()
    rng = np.random.default_rng(0)
    for i in range(count):
        cv2.imwrite(str(folder / f'frame_{i:03d}.png'),
                    rng.integers(0, 255, size=(H, W, 3), dtype=np.uint8))
    return str(folder)


def fake_cache(tmp_path, sizes, int8=()):
    """Return a model cache of crafted 'yolo11n-pose' files: fp32 ``sizes``, ``int8`` sizes."""
    cache = tmp_path / 'cache'
    cache.mkdir()
    out = np.zeros((1, 56, 8400), np.float32)
    out[0, :5, 0] = [100, 100, 50, 80, 0.9]
    for hw, precision in [(s, 'fp32') for s in sizes] + [(s, 'int8') for s in int8]:
        data = make_constant_model([('images', np.float32, [1, 3, *hw])], {'output0': out},
                                   {'task': 'pose'})
        path = models.model_file('yolo11n-pose', hw, str(cache), precision)
        open(path, 'wb').write(data)
        open(models.sidecar_file(path), 'w').write(json.dumps(
            {'name': 'yolo11n-pose', 'family': 'yolo-pose', 'input_size': list(hw),
             'precision': precision, 'onnx_sha256': hashlib.sha256(data).hexdigest()}))
    return str(cache)


def person_keypoints(rng, center, spread=120.0):
    """Return 17 original-pixel keypoints around ``center`` and their box."""
    kpts = np.asarray(center) + rng.uniform(-spread, spread, size=(17, 2))
    return kpts, np.concatenate([kpts.min(0) - 10, kpts.max(0) + 10])


def yolo_column(box_lb, kpts_in, score, conf):
    """Build one [56] YOLO output column in network-input pixels."""
    x0, y0, x1, y1 = box_lb
    col = np.zeros(56, np.float32)
    col[:5] = [(x0 + x1) / 2, (y0 + y1) / 2, x1 - x0, y1 - y0, score]
    col[5:] = np.concatenate([kpts_in, conf[:, None]], axis=1).reshape(-1)
    return col


def yolo_case_model(tmp_path):
    """
    Write a YOLO-pose ONNX whose output holds two people, a duplicate and a low-score box.

    Return its path and the people: (keypoints, box, score, confidences) in ``HD`` pixels.
    """
    rng = np.random.default_rng(0)
    lb = Letterbox.fit(HD, (640, 640))
    out = np.zeros((1, 56, 8400), np.float32)
    people = []
    for col, (center, score) in zip((100, 5000), (((600, 500), 0.9), ((1400, 600), 0.5))):
        kpts, box = person_keypoints(rng, center)
        conf = rng.uniform(0.3, 1.0, 17).astype(np.float32)
        conf[3] = 0.1                                     # below the keypoint threshold
        box_in = lb.to_input(box.reshape(2, 2)).reshape(4)
        out[0, :, col] = yolo_column(box_in, lb.to_input(kpts), score, conf)
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
    path = tmp_path / 'yolo.onnx'
    path.write_bytes(data)
    return str(path), people
