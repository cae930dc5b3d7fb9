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
Shelf proxy (the Shelf rig, 4 people milling about its shelf through a real detector's errors,
``test_calibrate.shelf_proxy``), Campus (3 cameras) and Panoptic 160906_band1 (5 and 10 of
its HD cameras), the last two through the simulated detector from their 3D ground truth: the
same errors, and PCP / MPJPE of tracking (``Fusion`` + the live output, as fusion_node) with
the estimated rig next to the true one. The estimated rig is first expressed in the true
one's frame by a similarity fitted to all camera centres and orientations
(``selfcal.align_to``, not robust), so the ground truth's frame applies; nothing is aligned
to the ground truth itself.
Refine: the Pose2Sim rig with cam_03 bumped by 3 deg and 10 cm, then ``--refine``.
``python bench/calibrate.py [--only pose2sim,shelf,campus,panoptic,refine]``
"""

import argparse
import contextlib
import io
import os
import re
import sys
import tempfile

import time

from mv3dpose_ros import cli
from mv3dpose_ros.core.geometry.calibration import load_calibration, save_rig_yaml
from mv3dpose_ros.core.selfcal.frame import align_to, camera_errors
from mv3dpose_ros.eval.sequence import GroundTruth, load_ground_truth
from mv3dpose_ros.sim.detector import detect, DetectorNoise
import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                'test'))
from test_calibrate import _bump, self_calibrate, shelf_proxy, track_score  # noqa: E402,I100

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


def sim_row(title: str, cams: dict, layout: str, views: list, gt, fps: float,
            frames=None, every: int = 1) -> None:
    """Calibrate from ``views`` (every ``every``-th frame), print errors and tracking figures."""
    t0 = time.process_time()
    res = self_calibrate(cams, views, layout, every)
    cpu = time.process_time() - t0
    aligned = errors_table(f'{title}, calibrated on {len(views[::every])} frames in '
                           f'{cpu:.0f} s CPU', res.cameras, cams)
    for name, rig in (('true', cams), ('estimated', aligned)):
        pcp, mm = track_score(rig, layout, views, gt, fps, frames)
        print(f'  tracking with the {name} rig: PCP {pcp:.1f}  MPJPE {mm:.1f} mm'
              + ('' if name == 'true' or set(aligned) == set(cams) else
                 f' (only the {len(aligned)} placed cameras)'))


def shelf(people: int, frames: int = 300, every: int = 2) -> None:
    """Print the Shelf proxy's row: Shelf rig, ``people`` people, a real detector's errors."""
    cams, gt, views = shelf_proxy(frames, people)
    ids = np.arange(people)
    truth = GroundTruth('coco17', {f: (ids, gt[f]) for f in range(frames)})
    sim_row(f'Shelf proxy ({people} people, {frames} frames at 25 fps, real-detector errors)',
            cams, 'coco17', views, truth, 25.0, range(10, frames), every)


def campus(every: int = 2) -> None:
    """Campus GT through the simulated detector (frames 300-799), scored on its test frames."""
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import campus_offline
    cams = load_calibration(campus_offline.CALIB)
    gt = load_ground_truth(campus_offline.DATA, 'campus')
    frames = np.arange(300, 800)
    poses = np.full((len(frames), 3, 14, 3), np.nan)
    for k, f in enumerate(frames):
        if int(f) in gt.frames:
            ids, p = gt.frames[int(f)]
            poses[k, ids] = p
    views, _ = detect(cams, poses, 'shelf14', DetectorNoise(), seed=1)
    shifted = GroundTruth('shelf14', {int(f) - 300: v for f, v in gt.frames.items()})
    test = [int(f) - 300 for f in gt.default_frames if 300 <= f < 800]
    sim_row('Campus (simulated detector, 3 people, frames 300-799)', cams, 'shelf14', views,
            shifted, 25.0, test, every)


def panoptic(count: int) -> None:
    """Panoptic band1 with ``count`` HD cameras through the simulated detector."""
    cal = os.path.join(PANOPTIC, 'calibration_160906_band1.json')
    hd = load_calibration(cal)
    names = list(hd)[::max(1, len(hd) // count)][:count]
    cams = {n: hd[n] for n in names}
    gt = load_ground_truth(PANOPTIC, 'panoptic')
    frames = sorted(gt.frames)
    n_people = max(int(ids.max()) + 1 for ids, _ in gt.frames.values())
    poses = np.full((len(frames), n_people, 19, 3), np.nan)
    for k, f in enumerate(frames):
        ids, p = gt.frames[f]
        poses[k, ids] = p
    views, _ = detect(cams, poses, 'panoptic19', DetectorNoise(), seed=1)
    shifted = GroundTruth('panoptic19', {k: gt.frames[f] for k, f in enumerate(frames)})
    sim_row(f'Panoptic band1, {count} HD cameras ({", ".join(names)}), {len(frames)} frames '
            '(simulated detector)', cams, 'panoptic19', views, shifted, 30.0)


def refine(tmp: str) -> None:
    """Bump cam_03 of the Qualisys rig by 3 deg and 10 cm; --refine; what moved."""
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
    parser.add_argument('--only', default='pose2sim,shelf,campus,panoptic,refine')
    args = parser.parse_args()
    only = args.only.split(',')
    with tempfile.TemporaryDirectory() as tmp:
        if 'pose2sim' in only:
            pose2sim(tmp)
        if 'shelf' in only:
            for people in (3, 4):
                shelf(people)
        if 'campus' in only:
            campus()
        if 'panoptic' in only:
            for count in (5, 10):
                panoptic(count)
        if 'refine' in only:
            refine(tmp)
    return 0


if __name__ == '__main__':
    sys.exit(main())
