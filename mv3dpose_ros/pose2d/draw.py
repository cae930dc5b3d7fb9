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

"""Draw 2D detections on an image (the pose2d node's debug image)."""

from typing import Sequence, Tuple

import cv2
from mv3dpose_ros.viz.palette import track_colour
import numpy as np


def draw_people(image: np.ndarray, keypoints: np.ndarray, boxes: np.ndarray,
                scores: np.ndarray, bones: Sequence[Tuple[int, int]],
                min_confidence: float = 0.3) -> np.ndarray:
    """
    Draw boxes, bones and joints of ``[P, J, 3]`` people on a BGR copy of ``image``.

    Only bones whose two joints reach ``min_confidence`` are drawn (no bogus connections).
    """
    out = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image.copy()
    thick = max(1, int(round(max(out.shape[:2]) / 500)))
    for i in range(keypoints.shape[0]):
        color = track_colour(i)
        x0, y0, x1, y1 = (int(round(v)) for v in boxes[i])
        cv2.rectangle(out, (x0, y0), (x1, y1), color, thick)
        cv2.putText(out, f'{scores[i]:.2f}', (x0, max(0, y0 - 4)), cv2.FONT_HERSHEY_SIMPLEX,
                    0.4 * thick, color, thick, cv2.LINE_AA)
        pts = keypoints[i]
        ok = pts[:, 2] >= min_confidence
        for a, b in bones:
            if ok[a] and ok[b]:
                cv2.line(out, (int(pts[a, 0]), int(pts[a, 1])), (int(pts[b, 0]), int(pts[b, 1])),
                         color, thick, cv2.LINE_AA)
        for x, y, _ in pts[ok]:
            cv2.circle(out, (int(x), int(y)), thick + 2, (255, 255, 255), -1, cv2.LINE_AA)
    return out
