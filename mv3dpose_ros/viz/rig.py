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
A picture of a calibrated rig: cameras, the people it was calibrated from, and the floor.

Top view (x, y) and side view (x, z), in the style of ``mv3dpose render``: each camera a
frustum from its centre with its name, the reconstructed joints as dots coloured per person,
and the floor (z = 0) as a line in the side view; unplaced cameras are listed in the title.
"""

from typing import Mapping, Optional, Sequence

import cv2
from mv3dpose_ros.core.geometry.camera import Camera
from mv3dpose_ros.viz.palette import track_colour
from mv3dpose_ros.viz.panels import draw_label, View
import numpy as np


def rig_picture(cameras: Mapping[str, Camera], points: np.ndarray,
                person: Optional[np.ndarray] = None, title: str = 'calibrated rig',
                unplaced: Sequence[str] = (), size: int = 560, max_points: int = 4000
                ) -> np.ndarray:
    """Return the top and side views of ``cameras`` and the joints ``points [M, 3]``."""
    pts = np.asarray(points, dtype=float).reshape(-1, 3)
    ok = np.isfinite(pts).all(1)
    pts = pts[ok]
    who = np.zeros(len(pts), int) if person is None else np.asarray(person)[ok]
    if len(pts) > max_points:
        keep = np.linspace(0, len(pts) - 1, max_points).astype(int)
        pts, who = pts[keep], who[keep]
    centres = np.array([c.center for c in cameras.values()]).reshape(-1, 3)
    everything = np.concatenate([centres, pts, np.zeros((1, 3))])
    lo, hi = everything.min(0) - 0.5, everything.max(0) + 0.5
    depth = 0.15 * float(np.max(hi - lo))
    panels = []
    for axes, names, name in (((0, 1), ('x', 'y'), 'top view'),
                              ((0, 2), ('x', 'z'), 'side view')):
        suffix = f' (not placed: {", ".join(unplaced)})' if unplaced else ''
        view = View(f'{title}: {name}{suffix}', axes, lo[list(axes)], hi[list(axes)],
                    (size, size), names)
        img = view.blank()
        if axes[1] == 2:
            a, b = view.px(np.array([[lo[0] - 10, 0, 0], [hi[0] + 10, 0, 0]]))
            cv2.line(img, tuple(map(int, a)), tuple(map(int, b)), (120, 160, 120), 2)
        for uv, k in zip(view.px(pts), who):
            cv2.circle(img, (int(uv[0]), int(uv[1])), 1, track_colour(int(k)), -1)
        for name_, cam in cameras.items():
            _frustum(img, view, cam, depth)
            draw_label(img, name_, view.px(cam.center) + np.array([0, -8]), (40, 40, 40), 0.4)
        panels.append(img)
    return np.concatenate(panels, axis=1)


def _frustum(img: np.ndarray, view: View, cam: Camera, depth: float) -> None:
    """Draw a camera as lines from its centre to its image corners at ``depth`` metres."""
    w, h = cam.width, cam.height
    corners = np.array([[0, 0], [w, 0], [w, h], [0, h]], dtype=float)
    rays = np.concatenate([(corners - cam.K[:2, 2]) / np.diag(cam.K)[:2], np.ones((4, 1))], 1)
    far = cam.center + depth * rays @ cam.R          # camera -> world: R^T x
    c = view.px(cam.center)
    f = view.px(far)
    colour = (60, 60, 60)
    for p in f:
        cv2.line(img, (int(c[0]), int(c[1])), (int(p[0]), int(p[1])), colour, 1, cv2.LINE_AA)
    for k in range(4):
        p, q = f[k], f[(k + 1) % 4]
        cv2.line(img, (int(p[0]), int(p[1])), (int(q[0]), int(q[1])), colour, 1, cv2.LINE_AA)
    cv2.circle(img, (int(c[0]), int(c[1])), 3, (0, 0, 0), -1)
