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
Benchmark the camera primitives the fusion calls every frame (median microseconds per call).

Uses a Panoptic HD camera (strong distortion, k1 = -0.29) when ../shared/data is present,
otherwise an equivalent synthetic one. Usage: ``python bench/bench_geometry.py [--repeat N]``
"""

import argparse
import os
import time

for _var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS'):
    os.environ[_var] = '1'

from mv3dpose_ros.core.geometry.calibration import load_calibration  # noqa: E402
from mv3dpose_ros.core.geometry.camera import Camera, fundamental_matrix  # noqa: E402
from mv3dpose_ros.core.skeleton import convert_poses  # noqa: E402
import numpy as np  # noqa: E402

DATA = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), '..',
                    'shared', 'data', 'panoptic_demo', 'camera_parameters.json')


def median_us(fn, repeat: int) -> float:
    """Return the median wall time of ``fn()`` in microseconds."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e6 * float(np.median(times))


def main() -> None:
    """Print the figures."""
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--repeat', type=int, default=2000)
    args = parser.parse_args()
    if os.path.exists(DATA):
        cams = load_calibration(DATA, cameras=['00_03', '00_06'])
        a, b = cams['00_03'], cams['00_06']
        source = 'Panoptic HD 00_03/00_06'
    else:
        K = [[1400.0, 0, 960], [0, 1400.0, 540], [0, 0, 1]]
        dist = [-0.29, 0.19, 0.0, 0.0, -0.05]
        a = Camera.look_at('a', K, [4, 0, 2], [0, 0, 1], 1920, 1080, dist=dist)
        b = Camera.look_at('b', K, [0, 4, 2], [0, 0, 1], 1920, 1080, dist=dist)
        source = 'synthetic'
    rng = np.random.default_rng(0)
    print(f'cameras: {source}; {args.repeat} repeats, median per call')
    for n in (17, 100, 1000):
        X = rng.uniform([-1, -1, 0], [1, 1, 2], (n, 3))
        uv = a.project(X)
        print(f'  {n:5d} points: project {median_us(lambda: a.project(X), args.repeat):7.1f} us'
              f'   undistort {median_us(lambda: a.undistort(uv), args.repeat):7.1f} us')
    print(f'  fundamental_matrix: {median_us(lambda: fundamental_matrix(a, b), args.repeat):.1f}'
          ' us')
    poses = rng.uniform(0, 1, (6, 17, 3))
    print(f'  convert_poses coco17->shelf14 (6 people): '
          f'{median_us(lambda: convert_poses(poses, "coco17", "shelf14"), args.repeat):.1f} us')


if __name__ == '__main__':
    main()
