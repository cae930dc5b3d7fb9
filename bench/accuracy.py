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
Accuracy of the whole pipeline (``Fusion.step``) on synthetic scenes and on projected real GT.

Prints tables of MOTA / ID switches / MPJPE / PCP for:

1. synthetic scenes (``mv3dpose_ros.sim``) over rig sizes and detector noise levels (noise
   ``xN`` = every rate and pixel error of the default ``DetectorNoise`` times N);
2. Campus ground truth (test frames 350-470, 650-750) projected into its 3 cameras through the
   simulated detector, scored with the VoxelPose PCP protocol;
3. Panoptic 160906_band1 ground truth (20 frames) projected into 5 HD cameras.

Deterministic (fixed seeds); figures, not assertions. Usage:
``python bench/accuracy.py [--frames N] [--noise 1,2,3] [--no-real]``
"""

import argparse
import os

from mv3dpose_ros.core.fusion.pipeline import Fusion
from mv3dpose_ros.core.geometry.calibration import load_calibration
from mv3dpose_ros.core.live.output import LiveOutput
from mv3dpose_ros.core.types import TrackState
from mv3dpose_ros.eval.sequence import evaluate_run, GroundTruth, load_ground_truth
from mv3dpose_ros.io.datasets import load_panoptic_gt
from mv3dpose_ros.sim import DetectorNoise, make_scene
from mv3dpose_ros.sim.detector import detect
import numpy as np

DATA = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), '..',
                    'shared', 'data')


def run_fusion(cameras, layout, views_seq, stamps):
    """
    Return ``frame -> (ids, poses)`` of the live output and the median reprojection px.

    The live output is what fusion_node publishes on ``~/tracks`` (``core.live.output``):
    confirmed and (for ``publish_coast_s``) coasting tracks.
    """
    fusion = Fusion(cameras, layout)
    output = LiveOutput(fusion.config.publish_coast_s)
    num_j = fusion.layout.num_joints
    hyps, reproj = {}, []
    for f, (views, stamp) in enumerate(zip(views_seq, stamps)):
        tracks = [t for t in output.step(fusion.step(views, stamp), stamp)[0]
                  if t.state in (TrackState.CONFIRMED, TrackState.COASTING)]
        hyps[f] = (np.array([t.track_id for t in tracks], dtype=int),
                   np.array([t.joints for t in tracks]).reshape(len(tracks), num_j, 3))
        for t in tracks:
            e = t.reprojection_error
            reproj.extend(e[np.isfinite(e)])
    return hyps, float(np.median(reproj)) if reproj else float('nan')


def row(name, rep, reproj):
    """Format one result line."""
    pcp = f'{100 * rep.pcp.average:5.1f}' if rep.pcp is not None else '  n/a'
    m = rep.mot
    return (f'{name:<28} MOTA {100 * m.mota:5.1f}  IDsw {m.id_switches:3d}  '
            f'FP {m.false_positives:4d}  FN {m.misses:4d}  '
            f'MPJPE {1000 * rep.mpjpe.mpjpe_m:6.1f} mm  PCP {pcp}  reproj {reproj:4.1f} px')


def synthetic(frames: int, noise_levels):
    """Print the synthetic table."""
    print(f'synthetic scenes, {frames} frames at 25 fps, people walking in a 3 m radius, '
          f'cameras on a 6 m circle (1280x720, 75 deg)')
    for scale in noise_levels:
        for cams, people in ((3, 3), (4, 4), (5, 6), (8, 8)):
            scene = make_scene(num_cameras=cams, num_people=people, num_frames=frames, seed=0,
                               noise=DetectorNoise().scaled(scale))
            hyps, reproj = run_fusion(scene.cameras, scene.layout, scene.views, scene.stamps)
            ids = np.arange(people)
            gt = GroundTruth(scene.layout, {f: (ids, scene.gt[f]) for f in range(frames)})
            rep = evaluate_run(scene.layout, hyps, gt)
            print(row(f'{cams} cams x {people} people, x{scale:g}', rep, reproj))


def campus(noise: DetectorNoise):
    """Print Campus figures (GT projected through the simulated detector)."""
    folder = os.path.join(DATA, 'campus')
    cams = load_calibration(os.path.join(folder, 'calibration_campus.json'))
    gt = load_ground_truth(folder, 'campus')
    for name, frames in (('350-470', np.r_[350:471]), ('650-750', np.r_[650:751])):
        poses = np.full((len(frames), 3, 14, 3), np.nan)
        for k, f in enumerate(frames):
            ids, p = gt.frames[int(f)]
            poses[k, ids] = p
        views, _ = detect(cams, poses, 'shelf14', noise, seed=0)
        hyps, reproj = run_fusion(cams, 'shelf14', views, frames / 25.0)
        hyps = {int(frames[k]): v for k, v in hyps.items()}
        rep = evaluate_run('shelf14', hyps, gt, frames=frames)
        print(row(f'Campus {name}', rep, reproj))
        print('   per actor PCP: ' + ', '.join(
            f'{a}: {100 * v:.1f}' for a, v in zip(rep.pcp.actor_ids, rep.pcp.per_actor)))


def panoptic(noise: DetectorNoise):
    """Print Panoptic band1 figures (GT projected into 5 HD cameras)."""
    folder = os.path.join(DATA, 'panoptic_160906_band1')
    names = ['00_03', '00_06', '00_12', '00_13', '00_23']
    cams = load_calibration(os.path.join(folder, 'calibration_160906_band1.json'),
                            cameras=names)
    gt = load_ground_truth(folder, 'panoptic')
    frames = sorted(gt.frames)
    _, poses = load_panoptic_gt(os.path.join(folder, 'hdPose3d_stage1_coco19')).as_array()
    views, _ = detect(cams, poses[..., :3], 'panoptic19', noise, seed=0)
    hyps, reproj = run_fusion(cams, 'panoptic19', views, np.array(frames) / 30.0)
    hyps = {frames[k]: v for k, v in hyps.items()}
    rep = evaluate_run('panoptic19', hyps, gt)
    n_ids = len({int(i) for v in hyps.values() for i in v[0]})
    print(row('Panoptic band1 (5 HD cams)', rep, reproj) + f'  track ids {n_ids}')


def main() -> None:
    """Parse arguments and print the tables."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--frames', type=int, default=200)
    parser.add_argument('--noise', default='1,2,3', help='noise scale factors')
    parser.add_argument('--no-real', action='store_true', help='skip Campus and Panoptic')
    args = parser.parse_args()
    synthetic(args.frames, [float(x) for x in args.noise.split(',')])
    if not args.no_real and os.path.isdir(DATA):
        print('real ground truth through the simulated detector (default noise)')
        campus(DetectorNoise())
        panoptic(DetectorNoise())


if __name__ == '__main__':
    main()
