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
``mv3dpose calibrate`` against known calibrations: figures, not assertions.

Pose2Sim (real OpenPose, 2 people, 4 cameras): per camera rotation error [deg] and centre
error [cm] against the Qualisys calibration after a similarity alignment, and
``mv3dpose track`` with either calibration (confirmed tracks, median reprojection error).
Campus (3 cameras) and Panoptic 160906_band1 (5 and 10 of its HD cameras), both through the
simulated detector from their 3D ground truth: the same errors, and for Campus PCP / MPJPE of
``mv3dpose track`` + ``mv3dpose eval`` with the estimated calibration (aligned onto the true
one by the same similarity, so the ground truth's frame applies) next to the true one.
Refine: the Pose2Sim rig with cam_03 bumped by 3 deg and 10 cm, then ``--refine``.
``python bench/calibrate.py [--only pose2sim,campus,panoptic,refine]``
"""

import argparse
import contextlib
import io
import json
import os
import re
import sys
import tempfile

import campus_offline
from mv3dpose_ros import cli
from mv3dpose_ros.core.calibration import load_calibration, save_rig_yaml
from mv3dpose_ros.core.selfcal import align_to, camera_errors
from mv3dpose_ros.eval.sequence import load_ground_truth
from mv3dpose_ros.sim.detector import detect, DetectorNoise
import numpy as np

SHARED = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), '..',
                      'shared', 'data')
P2S = os.path.join(SHARED, 'pose2sim_multiperson')
PANOPTIC = os.path.join(SHARED, 'panoptic_160906_band1')


def calibrate(*argv) -> tuple:
    """Run ``mv3dpose calibrate``; return (exit code, stdout)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = cli.main(['calibrate', *argv])
    if code not in (0, 3):
        print(err.getvalue(), file=sys.stderr)
    return code, out.getvalue()


def errors_table(title: str, est: dict, ref: dict) -> dict:
    """Print per camera errors after a similarity alignment; return the aligned rig."""
    aligned, _ = align_to(est, ref, robust=False)
    err = camera_errors(aligned, ref)
    print(f'{title}: ' + ', '.join(f'{n} {d:.2f} deg {100 * m:.1f} cm'
                                   for n, (d, m) in err.items())
          + f'; mean {np.mean([e[0] for e in err.values()]):.2f} deg '
            f'{100 * np.mean([e[1] for e in err.values()]):.1f} cm'
          + (f'; not placed: {", ".join(sorted(set(ref) - set(est)))}'
             if set(ref) - set(est) else ''))
    return aligned


def track(calib: str, poses: str, layout: str, fps: float, out: str) -> str:
    """Run ``mv3dpose track``; return its summary line."""
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        cli.main(['track', '--calibration', calib, '--poses', poses, '--layout', layout,
                  '--fps', str(fps), '-o', out, '--no-progress'])
    m = re.search(r'confirmed tracks: (\d+) \(ids [^)]*\); median reprojection error of '
                  r'confirmed joints ([\d.]+ px|n/a)', err.getvalue())
    return f'{m.group(1)} tracks, reprojection {m.group(2)}' if m else err.getvalue()[-300:]


def pose2sim(tmp: str) -> None:
    """Pose2Sim: errors vs Qualisys, tracking with both calibrations."""
    ref = load_calibration(os.path.join(P2S, 'Calib_qualisys.toml'))
    rig = os.path.join(tmp, 'p2s.yaml')
    calibrate('--calibration', os.path.join(P2S, 'Calib_qualisys.toml'), '--poses',
              os.path.join(P2S, 'pose'), '--layout', 'body25b', '-o', rig, '--no-picture')
    errors_table('Pose2Sim vs Qualisys', load_calibration(rig), ref)
    for name, calib in (('Qualisys', os.path.join(P2S, 'Calib_qualisys.toml')),
                        ('estimated', rig)):
        print(f'  mv3dpose track with the {name} calibration: '
              + track(calib, os.path.join(P2S, 'pose'), 'body25b', 60,
                      os.path.join(tmp, f'{name}.jsonl')))


def campus(tmp: str) -> None:
    """Campus through the simulated detector: errors, PCP / MPJPE with both calibrations."""
    folder = os.path.join(tmp, 'campus')
    campus_offline.write_openpose(folder, 1.0, 1, np.arange(300, 800))
    ref = load_calibration(campus_offline.CALIB)
    rig = os.path.join(tmp, 'campus.yaml')
    calibrate('--calibration', campus_offline.CALIB, '--poses', folder, '--layout', 'shelf14',
              '-o', rig, '--no-picture')
    aligned = errors_table('Campus (simulated detector, 3 people)', load_calibration(rig), ref)
    save_rig_yaml(aligned, os.path.join(tmp, 'campus_aligned.yaml'))
    true = campus_offline.score(folder, ['offline'], 'true')
    campus_offline.CALIB = os.path.join(tmp, 'campus_aligned.yaml')
    try:
        est = campus_offline.score(folder, ['offline'], 'est')
    finally:
        campus_offline.CALIB = os.path.join(campus_offline.DATA, 'calibration_campus.json')
    for name, r in (('true', true), ('estimated', est)):
        print(f'  track --smooth offline, {name} calibration: PCP {r["pcp"]:.1f}  '
              f'MOTA {r["mota"]:.1f}  MPJPE {r["mpjpe"]:.1f} mm')


def panoptic(tmp: str, count: int) -> None:
    """Panoptic band1 with ``count`` HD cameras through the simulated detector: errors."""
    cal = os.path.join(PANOPTIC, 'calibration_160906_band1.json')
    every = load_calibration(cal)
    names = list(every)[::max(1, len(every) // count)][:count]
    cams = {n: every[n] for n in names}
    gt = load_ground_truth(PANOPTIC, 'panoptic')
    frames = sorted(gt.frames)
    n_people = max(int(ids.max()) + 1 for ids, _ in gt.frames.values())
    poses = np.full((len(frames), n_people, 19, 3), np.nan)
    for k, f in enumerate(frames):
        ids, p = gt.frames[f]
        poses[k, ids] = p
    views, _ = detect(cams, poses, 'panoptic19', DetectorNoise(), seed=1)
    root = os.path.join(tmp, f'panoptic{count}')
    for n in names:
        os.makedirs(os.path.join(root, n))
        for k, f in enumerate(frames):
            people = [{'pose_keypoints_2d': np.nan_to_num(p).reshape(-1).tolist()}
                      for p in views[k][n]]
            with open(os.path.join(root, n, f'{f:06d}_keypoints.json'), 'w') as fh:
                json.dump({'people': people}, fh)
    rig = os.path.join(tmp, f'panoptic{count}.yaml')
    code, _ = calibrate('--calibration', cal, '--cameras', *names, '--poses', root,
                        '--layout', 'panoptic19', '-o', rig, '--no-picture')
    if code in (0, 3):
        errors_table(f'Panoptic band1, {count} cameras, {len(frames)} frames (simulated '
                     'detector)', load_calibration(rig), cams)


def refine(tmp: str) -> None:
    """Bump cam_03 of the Qualisys rig by 3 deg and 10 cm; --refine; what moved."""
    sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(
        os.path.abspath(__file__))), 'test'))
    from test_calibrate import _bump
    ref = load_calibration(os.path.join(P2S, 'Calib_qualisys.toml'))
    bumped = dict(ref)
    bumped['cam_03'] = _bump(ref['cam_03'], 3.0, 0.10)
    given = os.path.join(tmp, 'bumped.yaml')
    save_rig_yaml(bumped, given)
    out = os.path.join(tmp, 'refined.yaml')
    calibrate('--calibration', given, '--poses', os.path.join(P2S, 'pose'), '--layout',
              'body25b', '-o', out, '--refine', '--no-picture')
    est = load_calibration(out)
    moved, left = camera_errors(est, bumped), camera_errors(est, ref)
    print('Refine (cam_03 bumped by 3 deg, 10 cm): ' + ', '.join(
        f'{n} moved {d:.2f} deg {100 * m:.1f} cm (then off Qualisys by {left[n][0]:.2f} deg '
        f'{100 * left[n][1]:.1f} cm)' for n, (d, m) in moved.items()))


def main() -> int:
    """Print the comparisons."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--only', default='pose2sim,campus,panoptic,refine')
    args = parser.parse_args()
    only = args.only.split(',')
    with tempfile.TemporaryDirectory() as tmp:
        if 'pose2sim' in only:
            pose2sim(tmp)
        if 'campus' in only:
            campus(tmp)
        if 'panoptic' in only:
            for count in (5, 10):
                panoptic(tmp, count)
        if 'refine' in only:
            refine(tmp)
    return 0


if __name__ == '__main__':
    sys.exit(main())
