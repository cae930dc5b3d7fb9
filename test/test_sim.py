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


"""Synthetic scenes: determinism, plausible bodies and paths, detector error rates."""

from mv3dpose_ros.core.skeleton import get_layout
from mv3dpose_ros.sim import (DetectorNoise, make_rig, make_scene, RigConfig, simulate_people,
                              WalkConfig)
from mv3dpose_ros.sim.detector import detect
import numpy as np
import pytest

CLEAN = DetectorNoise.none()


def bone(gt: np.ndarray, layout: str, a: str, b: str) -> np.ndarray:
    lay = get_layout(layout)
    return np.linalg.norm(gt[..., lay.index(a), :] - gt[..., lay.index(b), :], axis=-1)


def test_same_seed_same_scene_other_seed_other_scene():
    a = make_scene(num_people=3, num_frames=30, seed=7)
    b = make_scene(num_people=3, num_frames=30, seed=7)
    c = make_scene(num_people=3, num_frames=30, seed=8)
    np.testing.assert_array_equal(a.gt, b.gt)
    for va, vb, sa, sb in zip(a.views, b.views, a.sources, b.sources):
        assert va.keys() == vb.keys()
        for k in va:
            np.testing.assert_array_equal(va[k], vb[k])
            np.testing.assert_array_equal(sa[k], sb[k])
    assert not np.allclose(a.gt, c.gt)
    # another detector model keeps the people and their paths
    d = a.redetect(CLEAN)
    np.testing.assert_array_equal(d.gt, a.gt)
    assert d.noise is CLEAN


def test_rig_looks_at_the_area_centre():
    cams = make_rig(RigConfig(num_cameras=6, radius_m=5.0, radius_y_m=3.0, height_m=3.0))
    assert list(cams) == [f'cam_{i:02d}' for i in range(1, 7)]
    for cam in cams.values():
        c = cam.center
        assert abs((c[0] / 5.0) ** 2 + (c[1] / 3.0) ** 2 - 1) < 1e-9 and c[2] == pytest.approx(3)
        uv = cam.project(np.array([0.0, 0.0, 1.0]))
        np.testing.assert_allclose(uv, [cam.width / 2, cam.height / 2], atol=1e-6)
    focal = make_rig(RigConfig(width=1000, hfov_deg=90.0))['cam_01'].K[0, 0]
    assert focal == pytest.approx(500.0)
    assert make_rig(num_cameras=2, dist=(-0.1, 0.01, 0, 0, 0))['cam_02'].has_distortion


def test_bodies_and_paths_are_plausible():
    walk = WalkConfig(area_radius_m=3.0, min_separation_m=0.7)
    gt, bodies, xy = simulate_people(5, 400, 25.0, 'body25b', walk, rng=np.random.default_rng(3))
    assert gt.shape == (400, 5, 25, 3) and np.isfinite(gt).all()
    for m, b in enumerate(bodies):
        assert 1.5 <= b.stature <= 1.98
        head = gt[:, m, get_layout('body25b').index('head_top'), 2]
        assert np.all(np.abs(head - b.stature) < 0.06 * b.stature)    # standing upright
    # bones: rigid over time, adult proportions, different between people
    for a, c, lo, hi in (('left_hip', 'left_knee', 0.34, 0.52),
                         ('left_knee', 'left_ankle', 0.34, 0.52),
                         ('right_shoulder', 'right_elbow', 0.25, 0.40),
                         ('right_elbow', 'right_wrist', 0.19, 0.31),
                         ('left_shoulder', 'right_shoulder', 0.28, 0.45),
                         ('left_hip', 'right_hip', 0.18, 0.30)):
        length = bone(gt, 'body25b', a, c)                             # [T, M]
        assert np.ptp(length, axis=0).max() < 1e-9, (a, c)
        assert lo < length.min() and length.max() < hi, (a, c, length[0])
    assert np.ptp(bone(gt, 'body25b', 'left_hip', 'left_knee')[0]) > 0.01
    lay = get_layout('body25b')
    ankles = gt[:, :, [lay.index('left_ankle'), lay.index('right_ankle')], 2]
    assert 0.04 < ankles.min() and np.median(ankles.min(-1)) < 0.1     # a foot on the ground
    # paths: inside the area, apart, walking speed, smooth (bounded acceleration)
    assert np.linalg.norm(xy, axis=-1).max() <= 3.0 + 1e-9
    d = np.linalg.norm(xy[:, :, None] - xy[:, None], axis=-1) + 10 * np.eye(5)
    assert d.min() > 0.69
    v = np.diff(xy, axis=0) * 25.0
    speed = np.linalg.norm(v, axis=-1)
    assert 0.6 < speed.mean() < 1.6 and speed.max() < 2.5
    assert np.linalg.norm(np.diff(v, axis=0) * 25.0, axis=-1).max() < 15.0
    # limbs swing: wrists and ankles move relative to the pelvis
    rel = gt[:, 0, lay.index('left_wrist')] - gt[:, 0, lay.index('left_hip')]
    assert np.ptp(rel[:, 2]) > 0.02 or np.ptp(np.linalg.norm(rel[:, :2], axis=-1)) > 0.05


def test_clean_detector_reproduces_projections_inside_images():
    scene = make_scene(num_cameras=5, num_people=4, num_frames=20, seed=2, noise=CLEAN)
    for t, (views, sources) in enumerate(zip(scene.views, scene.sources)):
        for name, cam in scene.cameras.items():
            poses, src = views[name], sources[name]
            assert poses.shape[1:] == (17, 3) and len(src) == len(poses)
            assert (src >= 0).all()
            proj = cam.project(scene.gt[t, src])
            seen = poses[..., 2] > 0
            np.testing.assert_allclose(poses[seen][:, :2], proj[seen], atol=1e-9)
            # joints outside the image are missing, never outside coordinates
            assert cam.in_image(poses[seen][:, :2]).all()
            assert not (cam.in_image(proj) & ~seen).any()


def test_noisy_detections_stay_in_images_and_sources_are_right():
    scene = make_scene(num_cameras=4, num_people=4, num_frames=40, seed=4,
                       noise=DetectorNoise(false_positive_rate=0.5))
    n_fp = 0
    for t, (views, sources) in enumerate(zip(scene.views, scene.sources)):
        for name, cam in scene.cameras.items():
            poses, src = views[name], sources[name]
            seen = poses[..., 2] > 0
            assert cam.in_image(poses[seen][:, :2]).all()
            assert ((poses[..., 2] > 0) <= 1).all() and (poses[~seen] == 0).all()
            n_fp += int((src < 0).sum())
            for p, s in zip(poses, src):
                if s < 0:
                    continue
                proj = cam.project(scene.gt[t, s])
                ok = p[:, 2] > 0
                err = np.linalg.norm(p[ok, :2] - proj[ok], axis=-1)
                perm = get_layout('coco17').flip_permutation
                flipped = np.linalg.norm(p[ok, :2] - proj[perm][ok], axis=-1)
                assert min(np.median(err), np.median(flipped)) < 10.0
    assert 0.25 * 160 < n_fp < 0.75 * 160           # Poisson(0.5) over 160 camera-frames


def _rates(noise: DetectorNoise, frames: int = 150, seed: int = 0):
    """Return a scene with wide spacing (no occlusion) seen through ``noise``."""
    walk = WalkConfig(area_radius_m=2.0, min_separation_m=1.0)
    rig = RigConfig(radius_m=9.0, hfov_deg=60.0)
    return make_scene(num_cameras=4, num_people=2, num_frames=frames, seed=seed, noise=noise,
                      rig=rig, walk=walk)


def test_error_rates_match_configuration():
    base = {**DetectorNoise.none().__dict__, 'occlusion_noise_factor': 1.0}
    clean = _rates(DetectorNoise(**base))
    n_clean = sum(len(v[c]) for v in clean.views for c in v)
    assert n_clean == 150 * 4 * 2                    # everyone visible everywhere
    # missed joints
    s = _rates(DetectorNoise(**{**base, 'joint_miss_rate': 0.1}))
    conf = np.concatenate([v[c][..., 2].ravel() for v in s.views for c in v])
    assert (conf == 0).mean() == pytest.approx(0.1, abs=0.02)
    # missed people
    s = _rates(DetectorNoise(**{**base, 'person_miss_rate': 0.2}))
    n = sum(len(v[c]) for v in s.views for c in v)
    assert 1 - n / n_clean == pytest.approx(0.2, abs=0.03)
    # false positives per camera and frame
    s = _rates(DetectorNoise(**{**base, 'false_positive_rate': 0.3}))
    fp = sum(int((src[c] < 0).sum()) for src in s.sources for c in src)
    assert fp / (150 * 4) == pytest.approx(0.3, abs=0.06)
    # pixel noise: residual std per axis
    s = _rates(DetectorNoise(**{**base, 'pixel_noise_px': 3.0}))
    res = []
    for t, (v, src) in enumerate(zip(s.views, s.sources)):
        for c, cam in s.cameras.items():
            res.append((v[c][..., :2] - cam.project(s.gt[t, src[c]])).reshape(-1, 2))
    res = np.concatenate(res)
    assert res.std() == pytest.approx(3.0, rel=0.05) and abs(res.mean()) < 0.1
    # left/right swaps
    s = _rates(DetectorNoise(**{**base, 'swap_rate': 0.25}))
    perm = get_layout('coco17').flip_permutation
    swapped = total = 0
    for t, (v, src) in enumerate(zip(s.views, s.sources)):
        for c, cam in s.cameras.items():
            for p, k in zip(v[c], src[c]):
                proj = cam.project(s.gt[t, k])
                total += 1
                swapped += np.abs(p[:, :2] - proj[perm]).max() < 1e-6
    assert swapped / total == pytest.approx(0.25, abs=0.04)


def test_occlusion_and_truncation():
    # two people in a row seen by a camera on that line: the far one loses joints
    cams = make_rig(num_cameras=1, radius_m=6.0, azimuth_offset_deg=0.0)
    gt, _, _ = simulate_people(1, 1, rng=np.random.default_rng(0))
    near = gt[0, 0] - gt[0, 0].mean(0) + [2.0, 0.0, gt[0, 0].mean(0)[2]]
    far = near - [3.0, 0.0, 0.0]
    joints = np.stack([near, far])[None]
    views, sources = detect(cams, joints, 'coco17',
                            DetectorNoise(**{**DetectorNoise.none().__dict__,
                                             'occlusion_drop_rate': 1.0}))
    by_src = dict(zip(sources[0]['cam_01'], views[0]['cam_01']))
    assert (by_src[0][:, 2] > 0).sum() == 17                         # the near one: complete
    far_visible = (by_src[1][:, 2] > 0).sum() if 1 in by_src else 0
    assert far_visible < 9                                           # the far one: hidden
    views, sources = detect(cams, joints, 'coco17', CLEAN)
    assert sorted(sources[0]['cam_01']) == [0, 1]                    # without occlusion: both
    # a person right in front of a camera is cut at the image border
    close = near + [3.5, 0.0, 0.0]                  # 0.5 m from the camera
    views, sources = detect(cams, close[None, None], 'coco17', CLEAN)
    poses = views[0]['cam_01']
    assert len(poses) == 0 or (poses[0][:, 2] > 0).sum() < 17
