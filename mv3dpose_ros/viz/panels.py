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
Metric panels: orthographic views of the world with a metre grid, and skeletons drawn on them.

``mv3dpose render`` draws tracks with these; the Foxglove scene check (``viz.scene``) draws what
a client received with the same views, so both pictures read alike. OpenCV and numpy only.
"""

import math
from typing import Optional, Sequence, Tuple

import cv2
from mv3dpose_ros.core.types import JointState
import numpy as np

BACKGROUND = (250, 250, 250)
GRID = (225, 225, 225)
AXIS_TEXT = (110, 110, 110)
FONT = cv2.FONT_HERSHEY_SIMPLEX


def valid_joints(track) -> np.ndarray:
    """
    Return the mask ``[J]`` of joints to draw: finite xyz and a state other than MISSING.

    ``track`` is a core ``Track`` or a tracks-file record (whose ``joint_state`` may be None).
    """
    ok = np.all(np.isfinite(np.asarray(track.joints, dtype=np.float64)), axis=1)
    if track.joint_state is not None and len(track.joint_state) == len(ok):
        ok &= np.asarray(track.joint_state) != JointState.MISSING
    return ok


class View:
    """A metric orthographic view: world axes (a, b) onto a panel, equal scale on both."""

    def __init__(self, title: str, axes: Tuple[int, int], lo: np.ndarray, hi: np.ndarray,
                 size: Tuple[int, int], names: Tuple[str, str]):
        """Fit the box ``lo``..``hi`` (metres, two values each) into ``size`` (w, h) px."""
        self.title, self.axes, self.names = title, axes, names
        self.w, self.h = size
        margin_top, margin = 34, 30
        span = np.maximum(hi - lo, 1e-3)
        self.scale = min((self.w - 2 * margin) / span[0], (self.h - margin_top - margin) / span[1])
        centre = 0.5 * (lo + hi)
        self.origin = np.array([self.w / 2, margin_top + (self.h - margin_top - margin) / 2])
        self.centre = centre
        self.flip = False         # True: the first axis grows to the left

    def px(self, X: np.ndarray) -> np.ndarray:
        """Map world points ``[..., 3]`` to panel pixels ``[..., 2]`` (second axis up)."""
        X = np.asarray(X, dtype=float)
        d = np.stack([X[..., self.axes[0]], X[..., self.axes[1]]], axis=-1) - self.centre
        return self.origin + d * np.array([-self.scale if self.flip else self.scale,
                                           -self.scale])

    def blank(self) -> np.ndarray:
        """Return the panel with its metre grid, axis names and title."""
        img = np.full((self.h, self.w, 3), BACKGROUND, np.uint8)
        half = np.array([self.w, self.h]) / (2 * self.scale)
        lo, hi = self.centre - half, self.centre + half
        step = 1.0 if max(hi - lo) > 3 else 0.5
        for k, (a, b) in enumerate(zip(lo, hi)):
            for v in np.arange(math.ceil(a / step) * step, b, step):
                sign = (-1 if self.flip else 1) if k == 0 else -1
                p = self.origin[k] + (v - self.centre[k]) * self.scale * sign
                p = int(round(p))
                if k == 0:
                    cv2.line(img, (p, 30), (p, self.h), GRID, 1)
                    cv2.putText(img, f'{v:g}', (p + 2, self.h - 6), FONT, 0.35, AXIS_TEXT, 1,
                                cv2.LINE_AA)
                elif p > 30:
                    cv2.line(img, (0, p), (self.w, p), GRID, 1)
                    cv2.putText(img, f'{v:g}', (3, p - 3), FONT, 0.35, AXIS_TEXT, 1,
                                cv2.LINE_AA)
        cv2.putText(img, f'{self.names[0]} [m]', (8 if self.flip else self.w - 60,
                    self.h - 20), FONT, 0.45, AXIS_TEXT, 1, cv2.LINE_AA)
        cv2.putText(img, f'{self.names[1]} [m]', (22, 46), FONT, 0.45, AXIS_TEXT, 1,
                    cv2.LINE_AA)
        cv2.rectangle(img, (0, 0), (self.w, 26), (235, 235, 235), -1)
        cv2.putText(img, self.title, (8, 19), FONT, 0.55, (40, 40, 40), 1, cv2.LINE_AA)
        cv2.rectangle(img, (0, 0), (self.w - 1, self.h - 1), (200, 200, 200), 1)
        return img


def draw_skeleton(img: np.ndarray, uv: np.ndarray, ok: np.ndarray, bones, colour,
                  thickness: int, radius: int, predicted: Optional[np.ndarray] = None,
                  dim: bool = False) -> None:
    """Draw bones and joints of one skeleton (hollow: ``predicted`` joints; pale: ``dim``)."""
    if dim:
        colour = tuple(int(0.45 * c + 0.55 * 255) for c in colour)
    pts = np.round(np.nan_to_num(uv)).astype(np.int64)
    for a, b in bones:
        if ok[a] and ok[b]:
            cv2.line(img, tuple(map(int, pts[a])), tuple(map(int, pts[b])), colour, thickness,
                     cv2.LINE_AA)
    for j in np.flatnonzero(ok):
        hollow = predicted is not None and predicted[j]
        cv2.circle(img, tuple(map(int, pts[j])), radius, colour, 1 if hollow else -1,
                   cv2.LINE_AA)


def draw_label(img: np.ndarray, text: str, at: Sequence[float], colour, scale: float = 0.5,
               thickness: int = 1) -> None:
    """Write ``text`` centred on ``at`` (its baseline) on a white box kept inside the image."""
    x, y = int(round(at[0])), int(round(at[1]))
    (tw, th), base = cv2.getTextSize(text, FONT, scale, thickness)
    x = min(max(x - tw // 2, 0), img.shape[1] - tw - 1)
    y = min(max(y, th + 2), img.shape[0] - base - 1)
    cv2.rectangle(img, (x - 2, y - th - 2), (x + tw + 2, y + base), (255, 255, 255), -1)
    cv2.putText(img, text, (x, y), FONT, scale, colour, thickness, cv2.LINE_AA)
