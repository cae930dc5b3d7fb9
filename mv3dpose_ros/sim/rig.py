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
Synthetic camera rigs: N cameras on an ellipse around an area, all looking at its centre.

Cameras are evenly spaced in azimuth (optionally jittered), mounted at ``height_m`` and aimed at
a point ``target_height_m`` above the area centre, like a typical motion-capture or
surveillance rig. Intrinsics come from the image size and either a focal length in pixels or
a horizontal field of view; distortion is OpenCV ``k1 k2 p1 p2 k3``.
"""

from dataclasses import dataclass
import math
from typing import Dict, Optional, Sequence, Tuple

from mv3dpose_ros.core.geometry.camera import Camera
import numpy as np


@dataclass
class RigConfig:
    """Geometry of a synthetic rig (metres, pixels, degrees)."""

    num_cameras: int = 4
    radius_m: float = 6.0                 # semi-axis along world x
    radius_y_m: Optional[float] = None    # semi-axis along world y (None: a circle)
    height_m: float = 2.5                 # camera centres above the ground
    target_height_m: float = 1.0          # aim point above the area centre
    center: Tuple[float, float] = (0.0, 0.0)
    width: int = 1280
    height: int = 720
    focal_px: Optional[float] = None      # None: from hfov_deg
    hfov_deg: float = 75.0
    dist: Sequence[float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    azimuth_offset_deg: float = 0.0       # azimuth of the first camera
    azimuth_jitter_deg: float = 0.0       # random per-camera azimuth perturbation
    height_jitter_m: float = 0.0
    name_format: str = 'cam_{:02d}'       # formatted with the camera number (1-based)

    def focal(self) -> float:
        """Return the focal length in pixels."""
        if self.focal_px is not None:
            return float(self.focal_px)
        return 0.5 * self.width / math.tan(math.radians(self.hfov_deg) / 2)


def make_rig(config: Optional[RigConfig] = None, seed: Optional[int] = 0,
             **overrides) -> Dict[str, Camera]:
    """
    Build the cameras of a rig, keyed by name in azimuth order.

    Keyword ``overrides`` replace fields of ``config`` (e.g. ``make_rig(num_cameras=8)``);
    ``seed`` drives the optional jitter.
    """
    cfg = config or RigConfig()
    if overrides:
        cfg = RigConfig(**{**cfg.__dict__, **overrides})
    if cfg.num_cameras < 1:
        raise ValueError(f'num_cameras must be >= 1, got {cfg.num_cameras}')
    if cfg.radius_m <= 0 or (cfg.radius_y_m is not None and cfg.radius_y_m <= 0):
        raise ValueError('rig radii must be positive')
    rng = np.random.default_rng(seed)
    f = cfg.focal()
    K = np.array([[f, 0, cfg.width / 2], [0, f, cfg.height / 2], [0, 0, 1.0]])
    ry = cfg.radius_m if cfg.radius_y_m is None else cfg.radius_y_m
    cx, cy = cfg.center
    target = np.array([cx, cy, cfg.target_height_m])
    cams = {}
    for i in range(cfg.num_cameras):
        az = math.radians(cfg.azimuth_offset_deg + 360.0 * i / cfg.num_cameras
                          + cfg.azimuth_jitter_deg * rng.uniform(-1, 1))
        eye = np.array([cx + cfg.radius_m * math.cos(az), cy + ry * math.sin(az),
                        cfg.height_m + cfg.height_jitter_m * rng.uniform(-1, 1)])
        name = cfg.name_format.format(i + 1)
        cams[name] = Camera.look_at(name, K, eye, target, cfg.width, cfg.height,
                                    dist=list(cfg.dist))
    return cams
