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
The rig's geometry as every stage of a step uses it, computed once per ``Fusion``.

Cameras are in rig order (the order of the calibration's names) everywhere: in the stacked 2D
poses, in ``members`` tables and in the per-camera arrays here.
"""

from dataclasses import dataclass
from typing import Dict, List, Mapping, Tuple

from mv3dpose_ros.core.fusion.association import camera_order, epipolar_norm_coefficients
from mv3dpose_ros.core.geometry.camera import Camera, essential_matrices
from mv3dpose_ros.core.geometry.triangulation import dlt_basis
from mv3dpose_ros.core.tracking.tracker import centroid
import numpy as np


@dataclass
class Rig:
    """Per-camera arrays of a calibrated rig, ``[C, ...]`` in rig order."""

    names: Tuple[str, ...]
    index: Dict[str, int]       # camera name -> rig index
    cameras: List[Camera]
    essentials: np.ndarray      # [C, C, 3, 3] essential matrices of every pair
    norm_coef: np.ndarray       # the epipolar distance's normalisation per pair
    order: np.ndarray           # [C] association order (wide-angle first)
    projections: np.ndarray     # [C, 3, 4] [R | t]
    basis: np.ndarray           # DLT basis of the projections
    focal: np.ndarray           # [C] pixels
    k: np.ndarray               # [C, 5] fx, skew, cx, fy, cy: pixels -> normalised
    distorted: List[bool]       # [C] needs undistortion (else the affine map above)
    bounds: np.ndarray          # [C, 4] x_min, x_max, y_min, y_max inside the image, normalised
    centres: np.ndarray         # [C, 3] camera centres in the world
    rotations: np.ndarray       # [C, 3, 3] world -> camera
    depth_rows: np.ndarray      # [C, 4] (R[2], t[2]): depth of a world point in each camera

    @classmethod
    def of(cls, cameras: Mapping[str, Camera]) -> 'Rig':
        """Return the geometry of ``cameras`` (at least two; ValueError naming the problem)."""
        if len(cameras) < 2:
            raise ValueError(f'Fusion needs at least two cameras, got {len(cameras)}: '
                             f'{sorted(cameras)}')
        names = tuple(cameras)
        cams = [cameras[n] for n in names]
        for name, cam in zip(names, cams):
            if not isinstance(cam, Camera):
                raise ValueError(f'camera {name!r} is a {type(cam).__name__}, not a Camera')
        essentials = essential_matrices(cams)
        projections = np.stack([np.hstack([c.R, c.t[:, None]]) for c in cams])
        return cls(
            names=names, index={n: i for i, n in enumerate(names)}, cameras=cams,
            essentials=essentials, norm_coef=epipolar_norm_coefficients(essentials),
            order=camera_order(np.array([c.R[2] for c in cams])), projections=projections,
            basis=dlt_basis(projections), focal=np.array([c.focal for c in cams]),
            k=np.array([[c.K[0, 0], c.K[0, 1], c.K[0, 2], c.K[1, 1], c.K[1, 2]] for c in cams]),
            distorted=[c.has_distortion for c in cams],
            bounds=np.array([_normalised_bounds(c) for c in cams]),
            centres=np.array([c.center for c in cams]), rotations=np.array([c.R for c in cams]),
            depth_rows=np.stack([np.append(c.R[2], c.t[2]) for c in cams]))

    def replace_camera(self, camera: Camera) -> None:
        """
        Put ``camera`` in the place of the rig's camera of its name (a corrected pose).

        Every array is rewritten in place: the parts of a ``Fusion`` that hold them see the
        new geometry at once, and nothing else changes.
        """
        if camera.name not in self.index:
            raise ValueError(f'camera {camera.name!r} is not in the rig ({", ".join(self.names)})')
        cams = dict(zip(self.names, self.cameras))
        cams[camera.name] = camera
        new = Rig.of(cams)
        for name, value in vars(new).items():
            old = getattr(self, name)
            if isinstance(old, np.ndarray):
                np.copyto(old, value)
            elif isinstance(old, list):
                old[:] = value

    def __len__(self) -> int:
        """Return the number of cameras."""
        return len(self.names)

    def cameras_in_view(self, poses: np.ndarray, per_camera: bool = False) -> np.ndarray:
        """
        Count, per pose ``[K, J, 3]``, the cameras whose image contains its joint centroid.

        ``per_camera``: return the ``[K, C]`` mask instead of the count.
        """
        centre = centroid(poses)                                            # [K, 3]
        cam = centre[:, None, None, :] @ self.projections[:, :, :3].transpose(0, 2, 1)
        cam = cam[:, :, 0] + self.projections[:, :, 3]                     # [K, C, 3]
        with np.errstate(invalid='ignore', divide='ignore'):
            x, y = cam[..., 0] / cam[..., 2], cam[..., 1] / cam[..., 2]
            b = self.bounds
            inside = (cam[..., 2] > 0) & (x >= b[:, 0]) & (x <= b[:, 1]) & (y >= b[:, 2]) \
                & (y <= b[:, 3])
        return inside if per_camera else inside.sum(axis=1)


def _normalised_bounds(cam: Camera, samples: int = 9) -> np.ndarray:
    """Return ``(x_min, x_max, y_min, y_max)`` of a box inside the undistorted image."""
    s = np.linspace(0.0, 1.0, samples)
    w, h = cam.width - 1.0, cam.height - 1.0
    edges = [np.stack([np.zeros_like(s), s * h], 1), np.stack([np.full_like(s, w), s * h], 1),
             np.stack([s * w, np.zeros_like(s)], 1), np.stack([s * w, np.full_like(s, h)], 1)]
    left, right, top, bottom = (cam.undistort(e) for e in edges)
    box = np.array([np.nanmax(left[:, 0]), np.nanmin(right[:, 0]),
                    np.nanmax(top[:, 1]), np.nanmin(bottom[:, 1])])
    return np.nan_to_num(box, nan=0.0)
