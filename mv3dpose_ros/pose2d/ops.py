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
Image and box operations shared by the model adapters: letterbox, its inverse, numpy NMS.

Coordinates map as in the transform the models were trained with (Ultralytics ``LetterBox``,
TensorFlow ``resize_with_pad``): ``x_input = x * scale + pad``. Its inverse therefore returns the
COCO annotation convention (pixel indices, as OpenCV's pixel-centre convention). It differs from
the exact image-content mapping of ``cv2.resize`` by half a pixel at most in the network input.
"""

from dataclasses import dataclass
from typing import Tuple

import cv2
import numpy as np


@dataclass(frozen=True)
class Letterbox:
    """
    Geometry of one letterbox: scale per axis, then pad to the network input size.

    ``scale_x``/``scale_y`` are the exact resize factors (content size / original size, which
    differ by rounding), ``left``/``top`` the padding before the content in pixels.
    """

    scale_x: float
    scale_y: float
    left: int
    top: int
    content_w: int
    content_h: int
    input_w: int
    input_h: int
    image_w: int
    image_h: int

    @classmethod
    def fit(cls, image_hw: Tuple[int, int], input_hw: Tuple[int, int]) -> 'Letterbox':
        """Plan the letterbox of an image of ``image_hw`` into ``input_hw`` (centred)."""
        h, w = int(image_hw[0]), int(image_hw[1])
        ih, iw = int(input_hw[0]), int(input_hw[1])
        if h <= 0 or w <= 0:
            raise ValueError(f'empty image ({w}x{h})')
        r = min(ih / h, iw / w)
        cw, ch = max(1, min(iw, int(round(w * r)))), max(1, min(ih, int(round(h * r))))
        left, top = (iw - cw) // 2, (ih - ch) // 2
        return cls(cw / w, ch / h, left, top, cw, ch, iw, ih, w, h)

    def apply(self, image: np.ndarray, pad_value: int = 114) -> np.ndarray:
        """Resize ``image`` ([H, W] or [H, W, C] uint8) into a padded array of the input size."""
        if image.shape[1] == self.content_w and image.shape[0] == self.content_h:
            content = image
        else:
            content = cv2.resize(image, (self.content_w, self.content_h),
                                 interpolation=cv2.INTER_LINEAR)
        return cv2.copyMakeBorder(content, self.top, self.input_h - self.content_h - self.top,
                                  self.left, self.input_w - self.content_w - self.left,
                                  cv2.BORDER_CONSTANT, value=(pad_value,) * 3)

    def inside(self, xy: np.ndarray) -> np.ndarray:
        """Return a mask ``[...]`` of original-image coordinates that lie within the image."""
        xy = np.asarray(xy)
        return ((xy[..., 0] >= -0.5) & (xy[..., 0] <= self.image_w - 0.5)
                & (xy[..., 1] >= -0.5) & (xy[..., 1] <= self.image_h - 0.5))

    def to_input(self, xy: np.ndarray) -> np.ndarray:
        """Map original-image pixel coordinates ``[..., 2]`` into the network input."""
        xy = np.asarray(xy, dtype=np.float64)
        out = np.empty_like(xy)
        out[..., 0] = xy[..., 0] * self.scale_x + self.left
        out[..., 1] = xy[..., 1] * self.scale_y + self.top
        return out

    def to_original(self, xy: np.ndarray) -> np.ndarray:
        """Map network-input pixel coordinates ``[..., 2]`` back to the original image."""
        xy = np.asarray(xy, dtype=np.float64)
        out = np.empty_like(xy)
        out[..., 0] = (xy[..., 0] - self.left) / self.scale_x
        out[..., 1] = (xy[..., 1] - self.top) / self.scale_y
        return out


def xywh_to_xyxy(boxes: np.ndarray) -> np.ndarray:
    """Convert centre/size boxes ``[N, 4]`` to corner boxes (x0, y0, x1, y1)."""
    boxes = np.asarray(boxes)
    half = boxes[:, 2:4] * 0.5
    return np.concatenate([boxes[:, :2] - half, boxes[:, :2] + half], axis=1)


def nms(boxes: np.ndarray, scores: np.ndarray, iou_threshold: float,
        max_keep: int = 300) -> np.ndarray:
    """
    Greedy class-agnostic non-maximum suppression; return kept indices, best score first.

    ``boxes`` are corner boxes ``[N, 4]``. A box is dropped when its IoU with a kept,
    higher-scoring box exceeds ``iou_threshold``.
    """
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    scores = np.asarray(scores, dtype=np.float64).reshape(-1)
    order = np.argsort(-scores, kind='stable')
    area = (np.clip(boxes[:, 2] - boxes[:, 0], 0, None)
            * np.clip(boxes[:, 3] - boxes[:, 1], 0, None))
    keep = []
    while order.size and len(keep) < max_keep:
        i = order[0]
        keep.append(i)
        rest = order[1:]
        x0 = np.maximum(boxes[i, 0], boxes[rest, 0])
        y0 = np.maximum(boxes[i, 1], boxes[rest, 1])
        x1 = np.minimum(boxes[i, 2], boxes[rest, 2])
        y1 = np.minimum(boxes[i, 3], boxes[rest, 3])
        inter = np.clip(x1 - x0, 0, None) * np.clip(y1 - y0, 0, None)
        union = area[i] + area[rest] - inter
        iou = np.divide(inter, union, out=np.zeros_like(inter), where=union > 0)
        order = rest[iou <= iou_threshold]
    return np.asarray(keep, dtype=np.int64)
