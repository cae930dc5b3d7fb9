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
Pinhole cameras with OpenCV radial-tangential distortion, and epipolar geometry.

Model: ``x_cam = R @ X + t`` (X in world metres, z up), normalised ``(x, y) = x_cam[:2] / z``,
distortion ``plumb_bob`` (k1, k2, p1, p2, k3, as OpenCV and ROS), then ``uv = K @ (x', y', 1)``.
A ``Camera`` validates itself on construction and is immutable by convention (its arrays are
read-only), so derived quantities are computed once.

Points whose normalised radius lies beyond the range where the radial polynomial is monotonic
(strong barrel distortion folds far off-axis points back into the image) project to NaN, like
points behind the camera, so a person outside a camera's field of view never shows up in it.
"""

from dataclasses import dataclass, field, replace
from typing import Optional, Sequence, Tuple

import cv2
import numpy as np

#: Tolerance on ``R @ R.T - I`` (max abs) and on ``det(R) - 1`` when validating rotations.
ROTATION_TOLERANCE = 1e-4
#: Largest plausible magnitudes: image side [px], K entries [px], distortion coefficients,
#: translation [m]. Beyond them a file is corrupt, and the numerics would overflow.
MAX_IMAGE_SIZE = 100_000
MAX_K = 1e7
MAX_DISTORTION = 1e4
MAX_TRANSLATION = 1e6
#: Crop or padding [px per dimension] that ``fit_image_size`` accepts by default: a codec pads
#: to a multiple of 16 (1080 -> 1088), so one macroblock.
IMAGE_SIZE_TOLERANCE_PX = 16


class CalibrationError(ValueError):
    """Bad or unreadable calibration; the message names the file, camera and field."""

    def __init__(self, reason: str, *, source: Optional[str] = None,
                 camera: Optional[str] = None, field: Optional[str] = None) -> None:
        self.reason, self.source, self.camera, self.field = reason, source, camera, field
        parts = []
        if source is not None:
            parts.append(str(source))
        if camera is not None:
            parts.append(f'camera {camera!r}')
        if field is not None:
            parts.append(f'field {field!r}')
        super().__init__(': '.join(parts + [reason]))

    def with_source(self, source: str) -> 'CalibrationError':
        """Return the same error attributed to file ``source``."""
        return CalibrationError(self.reason, source=source, camera=self.camera, field=self.field)


def _array(value, shape, name, camera) -> np.ndarray:
    try:
        arr = np.array(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise CalibrationError(f'not a numeric array: {repr(value)[:80]}', camera=camera,
                               field=name) from None
    if arr.size != int(np.prod(shape)):
        raise CalibrationError(f'has {arr.size} values, expected {int(np.prod(shape))} '
                               f'(shape {shape})', camera=camera, field=name)
    arr = arr.reshape(shape)
    if not np.isfinite(arr).all():
        raise CalibrationError('contains NaN or infinite values', camera=camera, field=name)
    return arr


def _bounded(arr: np.ndarray, limit: float, name: str, camera) -> np.ndarray:
    big = float(np.abs(arr).max()) if arr.size else 0.0
    if big > limit:
        raise CalibrationError(f'value {big:.6g} beyond the plausible range +-{limit:g}',
                               camera=camera, field=name)
    return arr


def _image_size(value, name, camera) -> int:
    try:
        size = float(value)
    except (TypeError, ValueError, OverflowError):
        raise CalibrationError(f'not a number: {repr(value)[:80]}', camera=camera,
                               field=name) from None
    if not np.isfinite(size) or size <= 0 or size != int(size) or size > MAX_IMAGE_SIZE:
        raise CalibrationError(f'must be a positive integer <= {MAX_IMAGE_SIZE}, got {value!r}',
                               camera=camera, field=name)
    return int(size)


def _max_radius2(dist: np.ndarray) -> float:
    """Return the squared normalised radius up to which radial distortion is monotonic."""
    k1, k2, k3 = dist[0], dist[1], dist[4]
    # d/dr [r (1 + k1 r^2 + k2 r^4 + k3 r^6)] = 1 + 3 k1 s + 5 k2 s^2 + 7 k3 s^3, s = r^2.
    roots = np.roots([7 * k3, 5 * k2, 3 * k1, 1.0]) if (k1 or k2 or k3) else []
    real = [r.real for r in roots if abs(r.imag) < 1e-12 and r.real > 0]
    return float(min(real)) if real else np.inf


def _readonly(arr: np.ndarray) -> np.ndarray:
    arr.setflags(write=False)
    return arr


@dataclass
class Camera:
    """A calibrated camera: intrinsics, distortion, world-to-camera pose and image size."""

    name: str
    K: np.ndarray        # (3, 3) intrinsics
    dist: np.ndarray     # (5,) k1 k2 p1 p2 k3 (4 or 0 values are padded with zeros)
    R: np.ndarray        # (3, 3) world -> camera rotation
    t: np.ndarray        # (3,) metres: x_cam = R @ X + t
    width: int
    height: int
    _K_inv: np.ndarray = field(init=False, repr=False, compare=False)
    _r2_max: float = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        """Validate and normalise the fields (CalibrationError naming camera and field)."""
        if not isinstance(self.name, str) or not self.name:
            raise CalibrationError(f'camera name must be a non-empty string, got {self.name!r}',
                                   field='name')
        name = self.name
        self.width = _image_size(self.width, 'width', name)
        self.height = _image_size(self.height, 'height', name)
        K = _bounded(_array(self.K, (3, 3), 'K', name), MAX_K, 'K', name)
        if not K.any():
            raise CalibrationError('all zeros (uncalibrated camera?)', camera=name, field='K')
        if not np.allclose(K[2], [0, 0, 1], atol=1e-9) or abs(K[1, 0]) > 1e-9:
            raise CalibrationError(f'not an upper-triangular intrinsics matrix with last row '
                                   f'[0, 0, 1]: {K.tolist()}', camera=name, field='K')
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise CalibrationError(f'focal lengths must be positive (fx={K[0, 0]}, '
                                   f'fy={K[1, 1]}); K is not invertible', camera=name, field='K')
        cx, cy = K[0, 2], K[1, 2]
        if not (0 <= cx <= self.width and 0 <= cy <= self.height):
            raise CalibrationError(
                f'principal point ({cx:g}, {cy:g}) outside the {self.width}x{self.height} '
                f'image (wrong or swapped width and height?)', camera=name, field='K')
        dist = np.zeros(5) if self.dist is None else np.array(self.dist, dtype=float).ravel()
        if dist.size in (0, 4):
            dist = np.concatenate([dist, np.zeros(5 - dist.size)])
        elif dist.size > 5 and np.all(dist[5:] == 0):
            dist = dist[:5]
        dist = _bounded(_array(dist, (5,), 'dist', name), MAX_DISTORTION, 'dist', name)
        R = _array(self.R, (3, 3), 'R', name)
        err = np.abs(R @ R.T - np.eye(3)).max()
        det = np.linalg.det(R)
        if err > ROTATION_TOLERANCE or abs(det - 1) > ROTATION_TOLERANCE:
            raise CalibrationError(f'not a rotation matrix (|R R^T - I| = {err:.2g}, '
                                   f'det = {det:.6g})', camera=name, field='R')
        u, _, vt = np.linalg.svd(R)   # remove rounding so E and F are exactly consistent
        R = u @ vt
        t = _bounded(_array(self.t, (3,), 't', name), MAX_TRANSLATION, 't', name)
        self.K, self.dist, self.R, self.t = map(_readonly, (K, dist, R, t))
        self._K_inv = _readonly(np.linalg.inv(K))
        self._r2_max = _max_radius2(dist)

    # ------------------------------------------------------------------ construction helpers
    @classmethod
    def from_pose(cls, name: str, K: np.ndarray, dist: Optional[Sequence[float]],
                  R_world_cam: np.ndarray, position: Sequence[float], width: int,
                  height: int) -> 'Camera':
        """Build a camera from its pose in the world (``T_world_cam``: rotation, centre)."""
        R_wc = _array(R_world_cam, (3, 3), 'R_world_cam', name)
        c = _array(position, (3,), 'position', name)
        return cls(name, K, dist, R_wc.T, -R_wc.T @ c, width, height)

    @classmethod
    def look_at(cls, name: str, K: np.ndarray, eye: Sequence[float], target: Sequence[float],
                width: int, height: int, dist: Optional[Sequence[float]] = None,
                up: Sequence[float] = (0.0, 0.0, 1.0)) -> 'Camera':
        """Build a camera at ``eye`` looking at ``target`` with image-up along world ``up``."""
        eye, target, up = (np.asarray(v, dtype=float) for v in (eye, target, up))
        z = target - eye
        if np.linalg.norm(z) == 0:
            raise CalibrationError('eye and target coincide', camera=name, field='target')
        z = z / np.linalg.norm(z)
        x = np.cross(z, up)   # image x to the right of the viewing direction
        if np.linalg.norm(x) < 1e-9:
            raise CalibrationError('viewing direction parallel to up', camera=name,
                                   field='target')
        x /= np.linalg.norm(x)
        y = np.cross(z, x)    # image y points down
        return cls.from_pose(name, K, dist, np.stack([x, y, z], axis=1), eye, width, height)

    # ------------------------------------------------------------------ derived quantities
    @property
    def center(self) -> np.ndarray:
        """Return the camera centre in world metres."""
        return -self.R.T @ self.t

    @property
    def P(self) -> np.ndarray:  # noqa: N802 (the usual name of the projection matrix)
        """Return the (3, 4) projection matrix K [R | t] (for undistorted pixels)."""
        return self.K @ np.hstack([self.R, self.t[:, None]])

    @property
    def focal(self) -> float:
        """Return the mean focal length in pixels (turns pixel thresholds into normalised)."""
        return float(0.5 * (self.K[0, 0] + self.K[1, 1]))

    @property
    def R_world_cam(self) -> np.ndarray:  # noqa: N802
        """Return the camera-to-world rotation (columns: camera axes in the world)."""
        return self.R.T

    @property
    def has_distortion(self) -> bool:
        """Tell whether any distortion coefficient is non-zero."""
        return bool(np.any(self.dist != 0))

    # ------------------------------------------------------------------ projection
    def to_camera(self, X: np.ndarray) -> np.ndarray:  # noqa: N803
        """Transform world points ``[..., 3]`` into the camera frame."""
        return np.asarray(X, dtype=float) @ self.R.T + self.t

    def distort(self, xy: np.ndarray) -> np.ndarray:
        """Apply distortion and K to normalised coordinates ``[..., 2]``; return pixels."""
        xy = np.asarray(xy, dtype=float)
        x, y = xy[..., 0], xy[..., 1]
        if self.has_distortion:
            k1, k2, p1, p2, k3 = self.dist
            r2 = x * x + y * y
            radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
            xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
            yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
            if self._r2_max < np.inf:
                folded = r2 > self._r2_max
                if folded.any():
                    xd = np.where(folded, np.nan, xd)
                    yd = np.where(folded, np.nan, yd)
            x, y = xd, yd
        K = self.K
        return np.stack([K[0, 0] * x + K[0, 1] * y + K[0, 2], K[1, 1] * y + K[1, 2]], axis=-1)

    def project(self, X: np.ndarray) -> np.ndarray:  # noqa: N803
        """
        Project world points ``[..., 3]`` (metres) to distorted pixels ``[..., 2]``.

        Points behind the camera (or beyond the monotonic distortion range) give NaN.
        """
        xc = self.to_camera(X)
        z = xc[..., 2]
        xy = xc[..., :2] / np.where(z > 0, z, np.nan)[..., None]   # NaN: no warning
        return self.distort(xy)

    def undistort(self, uv: np.ndarray) -> np.ndarray:
        """Map distorted pixels ``[..., 2]`` to normalised coordinates (x/z, y/z); NaN stays."""
        uv = np.asarray(uv, dtype=float)
        if uv.shape[-1:] != (2,):
            raise ValueError(f'expected pixel coordinates [..., 2], got shape {uv.shape}')
        flat = uv.reshape(-1, 2)
        ok = np.isfinite(flat).all(axis=1)
        everything = bool(ok.all())
        pts = flat if everything else flat[ok]
        if not self.has_distortion:
            K = self.K
            y = (pts[:, 1] - K[1, 2]) / K[1, 1]
            res = np.stack([(pts[:, 0] - K[0, 1] * y - K[0, 2]) / K[0, 0], y], axis=1)
        elif len(pts):
            res = cv2.undistortPoints(np.ascontiguousarray(pts).reshape(-1, 1, 2), self.K,
                                      self.dist, criteria=_UNDISTORT_CRITERIA).reshape(-1, 2)
        else:
            res = pts
        if everything:
            return res.reshape(uv.shape)
        out = np.full(flat.shape, np.nan)
        out[ok] = res
        return out.reshape(uv.shape)

    def undistort_pixels(self, uv: np.ndarray) -> np.ndarray:
        """Map distorted pixels ``[..., 2]`` to undistorted pixels (same K, no distortion)."""
        xy = self.undistort(uv)
        K = self.K
        return np.stack([K[0, 0] * xy[..., 0] + K[0, 1] * xy[..., 1] + K[0, 2],
                         K[1, 1] * xy[..., 1] + K[1, 2]], axis=-1)

    def in_image(self, uv: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Return the mask ``[...]`` of pixels inside the image (shrunk by ``margin`` px)."""
        uv = np.asarray(uv, dtype=float)
        with np.errstate(invalid='ignore'):
            return ((uv[..., 0] >= margin) & (uv[..., 0] <= self.width - margin)
                    & (uv[..., 1] >= margin) & (uv[..., 1] <= self.height - margin))


# Fixed-point iterations of cv2.undistortPoints: 20 reach 1e-12 px on the Panoptic HD lenses
# (k1 = -0.29) up to the image corners; its default (5) leaves 0.01 px there.
_UNDISTORT_CRITERIA = (cv2.TERM_CRITERIA_COUNT, 20, 0.0)


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])


def relative_pose(a: Camera, b: Camera):
    """Return (R, t) taking camera ``a`` coordinates to camera ``b``: x_b = R x_a + t."""
    R = b.R @ a.R.T
    return R, b.t - R @ a.t


def essential_matrix(a: Camera, b: Camera) -> np.ndarray:
    """Return E with ``x_b^T E x_a = 0`` for normalised homogeneous coordinates (x, y, 1)."""
    R, t = relative_pose(a, b)
    return _skew(t) @ R


def essential_matrices(cameras: Sequence[Camera]) -> np.ndarray:
    """Return the ``[C, C, 3, 3]`` table of pairwise essential matrices (zero where a = b)."""
    table = np.zeros((len(cameras), len(cameras), 3, 3))
    for a, cam_a in enumerate(cameras):
        for b, cam_b in enumerate(cameras):
            if a != b:
                table[a, b] = essential_matrix(cam_a, cam_b)
    return table


def turned(camera: Camera, rotation: np.ndarray) -> Camera:
    """Return ``camera`` turned by ``rotation`` (in its own frame) about its centre."""
    return replace(camera, R=rotation @ camera.R, t=rotation @ camera.t)


def turn_keypoints(camera: Camera, uv: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """
    Return pixels ``uv [..., 2]`` as the camera would see them after turning by ``rotation``.

    A camera that turns about its centre moves every image point by the homography of the
    rotation (what a kicked tripod does to the keypoints); distortion applies on both sides.
    NaN stays NaN.
    """
    xy = camera.undistort(uv)
    rays = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1) @ rotation.T
    with np.errstate(invalid='ignore', divide='ignore'):
        return camera.distort(rays[..., :2] / np.where(rays[..., 2:] > 0, rays[..., 2:], np.nan))


def fundamental_matrix(a: Camera, b: Camera) -> np.ndarray:
    """Return F with ``u_b^T F u_a = 0`` for undistorted homogeneous pixels (u, v, 1)."""
    return b._K_inv.T @ essential_matrix(a, b) @ a._K_inv


# ---------------------------------------------------------------------- image size vs calibration
@dataclass(frozen=True)
class ImageFit:
    """
    How keypoints of an image map to the pixel frame of the calibration the image differs from.

    ``kind``: 'same' (identity), 'scaled' (a resize with the same aspect ratio: per-axis factors
    about pixel centres), 'cropped' (a few pixels cropped or padded by a codec: identity, with
    the image origin assumed to be the calibration's) or 'mismatch' (nothing safe: drop).
    ``note`` says which and what was assumed, for a log line.
    """

    kind: str
    calib_size: Tuple[int, int]     # (width, height) the camera was calibrated at
    image_size: Tuple[int, int]     # (width, height) of the image the keypoints come from
    scale: Tuple[float, float] = (1.0, 1.0)   # calibration px per image px (x, y)
    note: str = ''

    @property
    def accepted(self) -> bool:
        """Tell whether keypoints of this image can be used (after ``apply``)."""
        return self.kind != 'mismatch'

    def apply(self, poses: np.ndarray) -> np.ndarray:
        """
        Return ``[..., J, 3]`` poses (x, y, confidence) in the calibration's pixel frame.

        Pixel-centre convention (as ``cv2.resize``): ``x' = (x + 0.5) * sx - 0.5``. Confidence
        and joints of confidence 0 (missing, zeroed by the decoder) are left as they are.
        """
        if not self.accepted:
            raise ValueError(f'no mapping from the image to the calibration: {self.note}')
        if self.scale == (1.0, 1.0):
            return np.asarray(poses, dtype=float)
        poses = np.array(poses, dtype=float)
        seen = poses[..., 2] > 0
        for axis, s in enumerate(self.scale):
            coord = poses[..., axis]
            coord[seen] = (coord[seen] + 0.5) * s - 0.5
        return poses


def _same_aspect(calib_w: int, calib_h: int, img_w: int, img_h: int) -> bool:
    """Tell whether one scale explains both sides up to a pixel of rounding per side."""
    lo = max((img_w - 1) / calib_w, (img_h - 1) / calib_h)
    hi = min((img_w + 1) / calib_w, (img_h + 1) / calib_h)
    return lo <= hi


def fit_image_size(calib_w: int, calib_h: int, img_w: int, img_h: int,
                   tolerance_px: int = IMAGE_SIZE_TOLERANCE_PX) -> ImageFit:
    """
    Decide how keypoints of an ``img_w x img_h`` image map to a ``calib_w x calib_h`` camera.

    Real rigs rarely deliver the calibrated size exactly: video codecs crop or pad to a multiple
    of 16 (1080 vs 1088) and detectors often run on resized streams. In order: equal sizes
    are 'same'; a difference of at most ``tolerance_px`` in each dimension is 'cropped' (scale
    1; the crop or padding is assumed at the right/bottom, i.e. both share the origin, as codecs
    do); the same aspect ratio (up to a pixel of rounding per side) is 'scaled'; anything else,
    e.g. a rotated (portrait vs landscape) or wrongly assigned camera, is 'mismatch'. A negative
    ``tolerance_px`` accepts equal sizes only.
    """
    calib, image = (int(calib_w), int(calib_h)), (int(img_w), int(img_h))
    if min(calib + image) <= 0:
        raise ValueError(f'image sizes must be positive: calibration {calib_w}x{calib_h}, '
                         f'image {img_w}x{img_h}')
    sizes = f'image {image[0]}x{image[1]} vs calibration {calib[0]}x{calib[1]}'
    if image == calib:
        return ImageFit('same', calib, image, note=f'{sizes}: same size')
    if tolerance_px < 0:
        return ImageFit('mismatch', calib, image, note=f'{sizes}: sizes must match exactly '
                        f'(negative tolerance)')
    dw, dh = image[0] - calib[0], image[1] - calib[1]
    if abs(dw) <= tolerance_px and abs(dh) <= tolerance_px:
        return ImageFit('cropped', calib, image, note=(
            f'{sizes}: taken as {_edges(dw, dh)} by the codec, keypoints unchanged (assumes '
            f'image and calibration share their origin: crop/padding at the right/bottom; a '
            f'crop at the left/top would offset the keypoints by that many pixels)'))
    if _same_aspect(*calib, *image):
        scale = (calib[0] / image[0], calib[1] / image[1])
        return ImageFit('scaled', calib, image, scale, note=(
            f'{sizes}: taken as a resize of the calibrated image (same aspect ratio), '
            f'keypoints scaled by {scale[0]:.6g} x {scale[1]:.6g} about pixel centres (assumes '
            f'the whole calibrated view was resized, not cropped)'))
    return ImageFit('mismatch', calib, image, note=(
        f'{sizes}: neither a resize (aspect ratio {image[0] / image[1]:.4f} vs '
        f'{calib[0] / calib[1]:.4f}) nor a crop or padding of at most {tolerance_px} px per '
        f'dimension (rotated or wrong camera?)'))


def _edges(dw: int, dh: int) -> str:
    """Name what a size difference of (dw, dh) image minus calibration pixels would be."""
    parts = []
    for d, side in ((dw, 'columns'), (dh, 'rows')):
        if d:
            parts.append(f'{abs(d)} {side} {"padded" if d > 0 else "cropped"}')
    return ' and '.join(parts)
