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
``mv3dpose track`` in the three output modes (live = ``--smooth causal``, what fusion_node
publishes on ``~/tracks``; ``--smooth fixed-lag --lag-frames 3``, its ``~/tracks_smoothed``;
``--smooth offline``) and scored with ``mv3dpose eval``. Prints PCP, MOTA, MPJPE and id
switches side by side per noise level, averaged over several detector seeds: figures, not
assertions. ``python bench/campus_offline.py [--noise 1,2] [--seeds 1,2,3] [--per-seed]
[--params FILE]`` (``FILE``: FusionConfig fields, as ``mv3dpose track --params``)
"""

import argparse
import contextlib
import io
import json
import os
import sys
import tempfile
from typing import Optional

from mv3dpose_ros import cli
from mv3dpose_ros.core.geometry.calibration import load_calibration
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


MODES = (('live', ['causal']), ('fixed-lag', ['fixed-lag', '--lag-frames', '3']),
         ('offline', ['offline']))


def score(folder: str, smooth: list, name: str, params: Optional[str] = None) -> dict:
    """Run ``mv3dpose track --smooth ...`` and ``mv3dpose eval``; return the eval figures."""
    tracks = os.path.join(folder, f'tracks_{name}.jsonl')
    figures = os.path.join(folder, f'eval_{name}.json')
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        assert cli.main(['track', '--calibration', CALIB, '--poses', folder, '--layout',
                         'shelf14', '--fps', '25', '--smooth', *smooth, '-o', tracks,
                         '--no-progress'] + (['--params', params] if params else [])) == 0
        assert cli.main(['eval', '--tracks', tracks, '--gt', DATA, '--format', 'campus',
                         '--json', figures]) == 0
    with open(figures, encoding='utf-8') as fh:
        r = json.load(fh)
    return {'pcp': 100 * r['pcp']['average'], 'mota': 100 * r['mot']['mota'],
            'mpjpe': 1000 * r['mpjpe_m'], 'idsw': r['mot']['id_switches']}


def main() -> int:
    """Print the table: per noise level, each mode averaged over the detector seeds."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--noise', default='1,2', help='detector noise scales (default 1,2)')
    parser.add_argument('--seeds', default='1,2,3', help='detector seeds (default 1,2,3)')
    parser.add_argument('--per-seed', action='store_true', help='also print every seed')
    parser.add_argument('--params', metavar='FILE',
                        help='FusionConfig fields for mv3dpose track (A/B of a setting)')
    args = parser.parse_args()
    if not os.path.isdir(DATA):
        print(f'no Campus data at {DATA}', file=sys.stderr)
        return 1
    seeds = [int(x) for x in args.seeds.split(',')]
    frames = np.arange(300, 800)
    print('Campus frames 300-799 through the simulated detector, scored on the test frames; '
          f'mean over detector seeds {seeds}')
    print('live = --smooth causal (= fusion_node ~/tracks), fixed-lag = --smooth fixed-lag '
          '--lag-frames 3 (= ~/tracks_smoothed), offline = --smooth offline')
    head = ' '.join(f'{name:>21}' for name, _ in MODES)
    print(f'{"noise":>5} {"":>6} {head}')
    print(f'{"":>5} {"":>6} ' + ' '.join(f'{"PCP  MOTA MPJPE IDsw":>21}' for _ in MODES))
    for scale in (float(x) for x in args.noise.split(',')):
        rows = {name: [] for name, _ in MODES}
        for seed in seeds:
            with tempfile.TemporaryDirectory() as folder:
                write_openpose(folder, scale, seed, frames)
                for name, smooth in MODES:
                    rows[name].append(score(folder, smooth, name, args.params))
            if args.per_seed:
                print(f'{scale:5g} {"s" + str(seed):>6} ' + ' '.join(
                    _cell(rows[name][-1]) for name, _ in MODES))
        mean = {name: {k: float(np.mean([r[k] for r in v])) for k in v[0]}
                for name, v in rows.items()}
        print(f'{scale:5g} {"mean":>6} ' + ' '.join(_cell(mean[name]) for name, _ in MODES))
    return 0


def _cell(r: dict) -> str:
    return f'{r["pcp"]:5.1f} {r["mota"]:5.1f} {r["mpjpe"]:5.1f} {r["idsw"]:4.1f}'


if __name__ == '__main__':
    sys.exit(main())
