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
The calibration watch against a bumped camera: time to name it, tracks after, the correction.

Every scene runs through ``LiveFusion.step_set`` (the live core of ``fusion_node`` and of
``mv3dpose track --smooth causal``). From the middle of the sequence one camera's keypoints
move exactly as a rotation of that camera about its centre moves them (a kicked tripod), about
an axis that changes with the size of the bump. For each mode of ``fusion.calibration_watch``
(off / warn / exclude / correct) it prints: the seconds from the bump to the warning naming
the camera, PCP and MPJPE of the published tracks after the bump (against the ground truth; on
the Pose2Sim real detections, which have none, MPJPE against the unbumped run's tracks), and
the corrected camera's remaining rotation error. Then false alarms: runs without a bump, with 0,
20 and 40 % of camera-frames dropped, must name no camera.

Scenes: ``sim5`` / ``sim4`` / ``sim3`` (simulated rigs, 3 people), ``shelf`` (the Shelf rig
with 4 people and the noise of a real detector), ``p2s`` (the Pose2Sim real detections, 4
cameras, 2 people, played forwards and back). Figures, not assertions::

    python bench/calibration_watch.py [--scenes sim5,shelf,p2s] [--degs 0.5,1,2,5]
                                      [--modes off,warn,exclude,correct] [--drops 0,0.2,0.4]
"""

import argparse
import glob
import os
import sys
import time

from mv3dpose_ros.core.fusion.pipeline import FusionConfig
from mv3dpose_ros.core.geometry.calibration import load_calibration
from mv3dpose_ros.core.geometry.camera import turn_keypoints, turned
from mv3dpose_ros.core.live.loop import LiveFusion, LiveLog
from mv3dpose_ros.core.live.sync import SyncConfig
from mv3dpose_ros.core.selfcal.watch import rotation_angle_deg, WatchConfig
from mv3dpose_ros.core.types import NS_PER_S, TrackState
from mv3dpose_ros.eval.sequence import evaluate_run, GroundTruth
from mv3dpose_ros.io.openpose import read_openpose_file
from mv3dpose_ros.sim import DetectorNoise, make_scene
from mv3dpose_ros.sim.detector import detect
from mv3dpose_ros.sim.people import simulate_people, WalkConfig
import numpy as np
from scipy.spatial.transform import Rotation

SHARED = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), '..',
                      'shared', 'data')
#: A real detector's errors on the Shelf rig (as test_calibrate's Shelf proxy).
REAL_DETECTOR = DetectorNoise(pixel_noise_px=3.0, relative_noise=0.01, joint_miss_rate=0.05,
                              person_miss_rate=0.05, false_positive_rate=0.1, swap_rate=0.03,
                              outlier_rate=0.02, outlier_px=60.0)
#: Bump axes (the camera's own x right, y down, z forward), one per bump size in turn.
AXES = ((0.3, 1.0, 0.2), (1.0, 0.2, 0.1), (0.2, 0.3, 1.0), (0.7, 0.7, 0.1))


def scene(name: str):
    """Return ``(cameras, layout, views, fps, gt or None)`` of a named scene."""
    if name.startswith('sim'):
        s = make_scene(num_cameras=int(name[3:]), num_people=3, num_frames=400, fps=25, seed=2)
        return s.cameras, s.layout, s.views, 25.0, s.gt
    if name == 'shelf':
        cams = load_calibration(os.path.join(SHARED, 'shelf', 'calibration_shelf.json'))
        walk = WalkConfig(area_radius_m=1.4, center=(0.45, -0.3), speed_range_mps=(0.3, 1.0),
                          min_separation_m=0.6)
        gt, _, _ = simulate_people(4, 400, 25.0, 'coco17', walk, None,
                                   np.random.default_rng(1))
        views, _ = detect(cams, gt, 'coco17', REAL_DETECTOR, seed=2)
        return cams, 'coco17', views, 25.0, gt
    if name == 'p2s':
        root = os.path.join(SHARED, 'pose2sim_multiperson')
        cams = load_calibration(os.path.join(root, 'Calib_qualisys.toml'))
        files = [sorted(glob.glob(os.path.join(d, '*.json')))
                 for d in sorted(glob.glob(os.path.join(root, 'pose', '*')))]
        frames = [{n: read_openpose_file(files[i][k]) for i, n in enumerate(cams)}
                  for k in range(len(files[0]))]
        return cams, 'body25b', (frames + frames[::-1][1:-1]) * 4, 60.0, None
    raise SystemExit(f'unknown scene {name!r}')


def run(cams, layout, views, fps, mode, deg=0.0, axis=AXES[0], drop=0.0, seed=0):
    """Run one sequence; return (named at frame, tracks per frame, rig at the end, ms/set)."""
    bumped, bump_at = list(cams)[1], len(views) // 2
    rotation = Rotation.from_rotvec(np.radians(deg) * np.asarray(axis) /
                                    np.linalg.norm(axis)).as_matrix()
    said = []
    log = LiveLog(info=lambda m: None, warning=said.append, throttled=lambda k, m: None)
    live = LiveFusion(list(cams), layout, SyncConfig(), FusionConfig(calibration_watch=mode),
                      log=log, watch_config=WatchConfig(mode=mode))
    live.start(cams)
    rng = np.random.default_rng(seed)
    named_at, frames, spent = None, [], 0.0
    for f, frame in enumerate(views):
        frame = dict(frame)
        if deg and f >= bump_at and len(frame[bumped]):
            poses = frame[bumped].copy()
            poses[..., :2] = turn_keypoints(cams[bumped], poses[..., :2], rotation)
            frame[bumped] = poses
        if drop:
            frame = {c: p for c, p in frame.items() if rng.random() >= drop}
        t0 = time.perf_counter()
        pubs = live.step_set(frame, int(round(f * NS_PER_S / fps)))
        spent += time.perf_counter() - t0
        if named_at is None and any('disagrees' in m for m in said):
            named_at = f
        tracks = [t for p in pubs if not p.smoothed for t in p.tracks
                  if t.state in (TrackState.CONFIRMED, TrackState.COASTING)]
        frames.append(tracks)
    err = rotation_angle_deg(live.cameras[bumped].R @ turned(cams[bumped], rotation).R.T)
    named = [m for m in said if 'disagrees' in m]
    return named_at, named, frames, err, 1e3 * spent / len(views), bump_at


def score(layout, frames, gt, start, reference=None):
    """Return (PCP %, MPJPE mm) of ``frames[start:]`` against ``gt`` or a reference run."""
    num = len(frames[0][0].joints) if any(frames) else 0
    hyps = {}
    for f in range(start, len(frames)):
        ts = frames[f]
        hyps[f] = (np.array([t.track_id for t in ts], dtype=int),
                   np.array([t.joints for t in ts]).reshape(len(ts), num, 3))
    if gt is None:
        ref = {f: (np.array([t.track_id for t in reference[f]], dtype=int),
                   np.array([t.joints for t in reference[f]]).reshape(len(reference[f]),
                                                                      num, 3))
               for f in range(start, len(reference))}
        truth = GroundTruth(layout, ref)
    else:
        truth = GroundTruth(layout, {f: (np.arange(len(gt[f])), gt[f])
                                     for f in range(start, len(gt))})
    rep = evaluate_run(layout, hyps, truth)
    return 100 * rep.pcp.average, 1000 * rep.mpjpe.mpjpe_m


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    ap.add_argument('--scenes', default='sim5,sim3,shelf,p2s')
    ap.add_argument('--degs', default='0.5,1,2,5')
    ap.add_argument('--modes', default='off,warn,exclude,correct')
    ap.add_argument('--drops', default='0,0.2,0.4')
    args = ap.parse_args()
    degs = [float(d) for d in args.degs.split(',')]
    modes = args.modes.split(',')
    print('| scene | bump | mode | named after (s) | PCP after / unbumped | MPJPE after (mm) '
          '| corrected error (deg) | watch+fusion ms/set |')
    print('|---|---|---|---|---|---|---|---|')
    for name in args.scenes.split(','):
        cams, layout, views, fps, gt = scene(name)
        _, _, clean, _, _, start = run(cams, layout, views, fps, 'off')
        base = score(layout, clean, gt, start, clean)
        for k, deg in enumerate(degs):
            for mode in modes:
                named_at, _, frames, err, ms, _ = run(cams, layout, views, fps, mode, deg,
                                                      AXES[k % len(AXES)])
                pcp, mpjpe = score(layout, frames, gt, start, clean)
                after = '-' if named_at is None else f'{(named_at - start) / fps:.2f}'
                fixed = f'{err:.2f}' if mode == 'correct' else '-'
                print(f'| {name} | {deg:g} deg | {mode} | {after} | {pcp:.1f} / {base[0]:.1f} '
                      f'| {mpjpe:.0f} | {fixed} | {ms:.2f} |', flush=True)
    print('\nfalse alarms (no bump; cameras named / runs):')
    for name in args.scenes.split(','):
        cams, layout, views, fps, _ = scene(name)
        for drop in (float(d) for d in args.drops.split(',')):
            alarms = sum(len(run(cams, layout, views, fps, 'correct', drop=drop, seed=s)[1])
                         for s in range(2))
            print(f'  {name}, {100 * drop:.0f} % of camera-frames dropped: {alarms} / 2',
                  flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
