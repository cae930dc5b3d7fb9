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
Campus through the offline tools, as a held-out OpenPose benchmark would run them.

The Campus ground truth (3 cameras, 360x288) goes through the simulated detector (pixel noise,
missed joints and people, false positives, left/right swaps, outliers; ``--noise`` scales
them), is written as OpenPose JSON folders named ``Camera0..2``, tracked with
``mv3dpose track`` (each ``--smooth`` mode) and scored with ``mv3dpose eval``. Prints PCP,
MPJPE, MOTA and id switches per noise level and mode: figures, not assertions.
"""

import argparse
import contextlib
import io
import json
import os
import sys
import tempfile

from mv3dpose_ros import cli
from mv3dpose_ros.core.calibration import load_calibration
from mv3dpose_ros.eval.sequence import load_ground_truth
from mv3dpose_ros.sim.detector import detect, DetectorNoise
import numpy as np

DATA = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), '..',
                    'shared', 'data', 'campus')
CALIB = os.path.join(DATA, 'calibration_campus.json')


def write_openpose(folder: str, scale: float, seed: int, frames: np.ndarray) -> None:
    """Write the detector's output on the Campus GT as OpenPose JSON folders."""
    cams = load_calibration(CALIB)
    gt = load_ground_truth(DATA, 'campus')
    poses = np.full((len(frames), 3, 14, 3), np.nan)
    for k, f in enumerate(frames):
        if int(f) in gt.frames:
            ids, p = gt.frames[int(f)]
            poses[k, ids] = p
    views, _ = detect(cams, poses, 'shelf14', DetectorNoise().scaled(scale), seed=seed)
    for cam in cams:
        os.makedirs(os.path.join(folder, f'Camera{cam}'), exist_ok=True)
    for k, f in enumerate(frames):
        for cam in cams:
            people = [{'pose_keypoints_2d': np.nan_to_num(p).reshape(-1).tolist()}
                      for p in views[k][cam]]
            path = os.path.join(folder, f'Camera{cam}', f'{int(f):06d}_keypoints.json')
            with open(path, 'w', encoding='utf-8') as fh:
                json.dump({'version': 1.3, 'people': people}, fh)


def score(folder: str, smooth: str) -> dict:
    """Run ``mv3dpose track`` and ``mv3dpose eval``; return the eval figures."""
    tracks = os.path.join(folder, f'tracks_{smooth}.jsonl')
    figures = os.path.join(folder, f'eval_{smooth}.json')
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        assert cli.main(['track', '--calibration', CALIB, '--poses', folder, '--layout',
                         'shelf14', '--fps', '25', '--smooth', smooth, '-o', tracks,
                         '--no-progress']) == 0
        assert cli.main(['eval', '--tracks', tracks, '--gt', DATA, '--format', 'campus',
                         '--json', figures]) == 0
    with open(figures, encoding='utf-8') as fh:
        return json.load(fh)


def main() -> int:
    """Print the table."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--noise', default='1,2', help='detector noise scales (default 1,2)')
    parser.add_argument('--seed', type=int, default=1)
    args = parser.parse_args()
    if not os.path.isdir(DATA):
        print(f'no Campus data at {DATA}', file=sys.stderr)
        return 1
    frames = np.arange(300, 800)
    print('Campus frames 300-799 through the simulated detector, scored on the test frames')
    print(f'{"noise":>5} {"smooth":>8} {"PCP %":>6} {"MPJPE mm":>9} {"MOTA %":>7} {"IDsw":>5}')
    for scale in (float(x) for x in args.noise.split(',')):
        with tempfile.TemporaryDirectory() as folder:
            write_openpose(folder, scale, args.seed, frames)
            for smooth in ('offline', 'causal', 'none'):
                r = score(folder, smooth)
                print(f'{scale:5g} {smooth:>8} {100 * r["pcp"]["average"]:6.1f} '
                      f'{1000 * r["mpjpe_m"]:9.1f} {100 * r["mot"]["mota"]:7.1f} '
                      f'{r["mot"]["id_switches"]:5d}')
    return 0


if __name__ == '__main__':
    sys.exit(main())
