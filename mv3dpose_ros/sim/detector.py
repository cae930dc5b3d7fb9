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
A 2D pose detector model: turns ground-truth 3D joints into the detections a real one makes.

Per camera and frame, each person is projected with the camera's distortion and then, in this
order (all rates are probabilities per item, all deterministic given the generator):

1. truncation: joints outside the image (less ``border_px``) or behind the camera are lost;
   people with fewer than ``min_visible_joints`` left are not detected;
2. occlusion: a joint that falls inside the (padded) 2D box of a person nearer to the camera
   is dropped with ``occlusion_drop_rate``, otherwise its noise grows by
   ``occlusion_noise_factor`` and its confidence drops;
3. missed people (``person_miss_rate``) and missed joints (``joint_miss_rate``);
4. pixel noise: Gaussian, ``pixel_noise_px`` plus ``relative_noise`` times the person's 2D
   height; a few joints (``outlier_rate``) land far off (``outlier_px``) with low confidence;
5. left/right swaps of the whole person (``swap_rate``), the classic detector confusion;
6. false positives: on average ``false_positive_rate`` per camera and frame (Poisson), a
   person-shaped pose of a random body standing at a random place, seen only in this camera.

Detections come out in random order (a detector knows nothing about identities), as raw
pixels ``[P, J, 3]`` with confidences in (0, 1], missing joints as (0, 0, 0). The index of
the ground-truth person behind each detection (-1 for false positives) is returned too.
"""

from dataclasses import dataclass
from typing import Dict, Mapping, Optional, Tuple
import warnings

from mv3dpose_ros.core.geometry.camera import Camera
from mv3dpose_ros.core.skeleton import get_layout
import numpy as np


@dataclass
class DetectorNoise:
    """Error rates of the simulated detector (pixels, probabilities)."""

    pixel_noise_px: float = 2.0
    relative_noise: float = 0.005        # extra std as a fraction of the person's 2D height
    joint_miss_rate: float = 0.03
    person_miss_rate: float = 0.02
    false_positive_rate: float = 0.05    # expected false detections per camera and frame
    swap_rate: float = 0.01
    outlier_rate: float = 0.005
    outlier_px: float = 40.0
    occlusion_drop_rate: float = 0.5
    occlusion_pad: float = 0.05          # box padding as a fraction of the occluder's height
    occlusion_noise_factor: float = 2.0  # noise multiplier of occluded joints that are kept
    border_px: float = 0.0
    min_visible_joints: int = 5
    confidence_mean: float = 0.85
    confidence_std: float = 0.08

    @classmethod
    def none(cls) -> 'DetectorNoise':
        """Return a perfect detector (only truncation at the image borders remains)."""
        return cls(pixel_noise_px=0.0, relative_noise=0.0, joint_miss_rate=0.0,
                   person_miss_rate=0.0, false_positive_rate=0.0, swap_rate=0.0,
                   outlier_rate=0.0, occlusion_drop_rate=0.0, confidence_std=0.0,
                   min_visible_joints=1)

    def scaled(self, factor: float) -> 'DetectorNoise':
        """Return a copy with every error rate and noise level multiplied by ``factor``."""
        keys = ('pixel_noise_px', 'relative_noise', 'joint_miss_rate', 'person_miss_rate',
                'false_positive_rate', 'swap_rate', 'outlier_rate', 'occlusion_drop_rate')
        d = dict(self.__dict__)
        for k in keys:
            d[k] = d[k] * factor
        for k in ('joint_miss_rate', 'person_miss_rate', 'swap_rate', 'outlier_rate',
                  'occlusion_drop_rate'):
            d[k] = min(d[k], 1.0)
        return DetectorNoise(**d)


def _boxes(uv: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Return ``[P, 4]`` boxes (x0, y0, x1, y1) of the visible joints (NaN if none)."""
    pts = np.where(ok[..., None], uv, np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', RuntimeWarning)    # all-NaN people
        return np.concatenate([np.nanmin(pts, axis=1), np.nanmax(pts, axis=1)], axis=1)


def detect_view(camera: Camera, joints: np.ndarray, layout: str, noise: DetectorNoise,
                rng: np.random.Generator,
                fp_pool: Optional[np.ndarray] = None) -> Tuple[np.ndarray, np.ndarray]:
    """
    Detect the people ``joints [M, J, 3]`` (metres, NaN = absent) in one camera.

    Returns ``(poses [P, J, 3] raw pixels + confidence, source [P])`` where ``source`` is the
    index into ``joints`` or -1 for a false positive. ``fp_pool [K, J, 3]`` are 3D poses
    false positives are drawn from (default: shifted copies of ``joints``).
    """
    lay = get_layout(layout)
    joints = np.asarray(joints, dtype=float).reshape(-1, lay.num_joints, 3)
    m, j = joints.shape[:2]
    uv = camera.project(joints)                                       # [M, J, 2]
    depth = camera.to_camera(joints)[..., 2]
    ok = np.isfinite(uv).all(-1) & camera.in_image(uv, noise.border_px) & (depth > 0)
    conf = np.clip(rng.normal(noise.confidence_mean, noise.confidence_std, (m, j)), 0.05, 1.0)
    std = np.full((m, j), noise.pixel_noise_px)
    box = _boxes(uv, ok)
    height = box[:, 3] - box[:, 1]
    std += noise.relative_noise * np.nan_to_num(height)[:, None]
    # occlusion by nearer people
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', RuntimeWarning)
        person_depth = np.nanmedian(np.where(ok, depth, np.nan), axis=1) if m else np.zeros(0)
    for a in range(m):
        for b in range(m):
            if a == b or not (person_depth[b] < person_depth[a]) or not ok[b].any():
                continue
            pad = noise.occlusion_pad * height[b]
            inside = ((uv[a, :, 0] >= box[b, 0] - pad) & (uv[a, :, 0] <= box[b, 2] + pad)
                      & (uv[a, :, 1] >= box[b, 1] - pad) & (uv[a, :, 1] <= box[b, 3] + pad))
            hidden = inside & ok[a]
            drop = hidden & (rng.uniform(size=j) < noise.occlusion_drop_rate)
            ok[a] &= ~drop
            std[a] = np.where(hidden & ~drop, noise.occlusion_noise_factor * std[a], std[a])
            conf[a] = np.where(hidden & ~drop, 0.6 * conf[a], conf[a])
    ok &= rng.uniform(size=(m, j)) >= noise.joint_miss_rate
    detected = (ok.sum(1) >= noise.min_visible_joints) & (
        rng.uniform(size=m) >= noise.person_miss_rate)
    det = uv + rng.normal(size=(m, j, 2)) * std[..., None]
    outlier = ok & (rng.uniform(size=(m, j)) < noise.outlier_rate)
    ang = rng.uniform(0, 2 * np.pi, size=(m, j))
    det = np.where(outlier[..., None], det + noise.outlier_px * np.stack(
        [np.cos(ang), np.sin(ang)], -1), det)
    conf = np.where(outlier, 0.5 * conf, conf)
    ok &= camera.in_image(det)                # noise may push a border joint out
    poses = np.concatenate([np.nan_to_num(det), conf[..., None]], -1)
    poses[~ok] = 0.0
    swap = rng.uniform(size=m) < noise.swap_rate
    if swap.any():
        poses[swap] = poses[swap][:, lay.flip_permutation]
    poses, source = poses[detected], np.flatnonzero(detected)
    # false positives
    n_fp = rng.poisson(noise.false_positive_rate) if noise.false_positive_rate > 0 else 0
    if n_fp:
        pool = fp_pool if fp_pool is not None and len(fp_pool) else joints
        fps = []
        for _ in range(n_fp * 3):     # a few attempts: the ghost must be visible
            if len(fps) == n_fp or not len(pool):
                break
            base = pool[rng.integers(len(pool))]
            root = np.nanmean(base, axis=0)
            # a random place at 1-10 m in front of the camera, turned at random
            d = rng.uniform(1.5, 10.0)
            ray = camera.R.T @ np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.2, 0.2), 1.0])
            spot = camera.center + d * ray / np.linalg.norm(ray)
            turn = rng.uniform(0, 2 * np.pi)
            c, s = np.cos(turn), np.sin(turn)
            rot = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
            ghost = (base - root) @ rot.T + np.array([spot[0], spot[1], root[2]])
            guv = camera.project(ghost)
            gok = np.isfinite(guv).all(-1) & camera.in_image(guv, noise.border_px)
            gok &= rng.uniform(size=j) >= 2 * noise.joint_miss_rate
            if gok.sum() < noise.min_visible_joints:
                continue
            gconf = np.clip(rng.normal(0.45, 0.12, j), 0.05, 0.9)
            guv = guv + rng.normal(size=(j, 2)) * 3.0 * max(noise.pixel_noise_px, 1.0)
            gok &= camera.in_image(guv)
            g = np.concatenate([np.nan_to_num(guv), gconf[:, None]], -1)
            g[~gok] = 0.0
            fps.append(g)
        if fps:
            poses = np.concatenate([poses, np.stack(fps)])
            source = np.concatenate([source, np.full(len(fps), -1)])
    order = rng.permutation(len(poses))
    return poses[order].reshape(-1, j, 3), source[order].astype(int)


def detect(cameras: Mapping[str, Camera], joints: np.ndarray, layout: str,
           noise: Optional[DetectorNoise] = None, seed: Optional[int] = 0,
           rng: Optional[np.random.Generator] = None
           ) -> Tuple[list, list]:
    """
    Detect a sequence ``joints [T, M, J, 3]`` in every camera.

    Returns ``(views, sources)``: per frame a dict camera -> ``[P, J, 3]`` and a dict camera
    -> ``[P]`` GT person indices (-1 = false positive). People absent in a frame have NaN
    joints. Deterministic for a given ``seed`` (or generator).
    """
    noise = noise or DetectorNoise()
    rng = rng if rng is not None else np.random.default_rng(seed)
    joints = np.asarray(joints, dtype=float)
    pool = joints.reshape(-1, *joints.shape[-2:])
    pool = pool[np.isfinite(pool).all((1, 2))]
    views, sources = [], []
    for t in range(joints.shape[0]):
        present = np.isfinite(joints[t]).any((1, 2))
        idx = np.flatnonzero(present)
        v: Dict[str, np.ndarray] = {}
        s: Dict[str, np.ndarray] = {}
        for name, cam in cameras.items():
            poses, src = detect_view(cam, joints[t, idx], layout, noise, rng, pool)
            v[name] = poses
            s[name] = np.where(src >= 0, idx[np.clip(src, 0, None)] if len(idx) else -1, -1)
        views.append(v)
        sources.append(s)
    return views, sources
