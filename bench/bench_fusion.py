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
Benchmark ``Fusion.step``: median milliseconds per synchronised set on one core.

Every case runs the whole pipeline (association, triangulation with gates, tracking, causal
smoothing, single-view ray updates) in-process on recorded inputs, as it would run live:

- ``complete CxP``: a synthetic scene (``mv3dpose_ros.sim``: cameras on a circle, people
  walking in its inner half, default detector noise), every person inside every camera: the
  set path only. The reference implementation's published figures are printed beside it.
- ``partial CxP``: the same rig with narrower lenses and people walking out to its edge, so
  joints behind or outside a camera are missing and views lack people, as on real rigs: more
  tracks coast, poses are left over for the single-view path, tracks seen by disjoint cameras
  are checked for duplicates.
- ``pose2sim``: the real OpenPose BODY_25B detections of Pose2Sim's multi-person session (4
  distorted cameras, 2 people, 100 frames at 60 fps; ``../shared/data``).
- ``shelf``: the Shelf rig, 4 people milling about its shelf through a real detector's
  errors (the scene of ``test_calibrate.shelf_proxy``), 25 fps.

``--against TREE[,TREE]`` times the same inputs through the ``Fusion`` of other source trees
(e.g. ``git worktree add /tmp/wt_old <commit>``; the old flat ``core`` works too), loaded side
by side in this process and stepped frame by frame in turn (the order rotating), so every
tree meets the same load on a shared machine. Per case and tree: ``floor``, the median over
frames of each frame's fastest run (the figure other processes move least), and ``median``,
of the runs' medians; with trees, ``[0]/[k]``, the median of the paired per-frame ratios of
this tree's time to tree k's. Each run starts after a garbage collection. Figures, never
assertions.

Usage: ``python bench/bench_fusion.py [--cases complete,partial,pose2sim,shelf]
[--configs 4x2,5x4,16x6] [--frames N] [--repeat R] [--against TREE,...] [--clock cpu|wall]
[--profile CASE]`` (``CASE`` as printed, e.g. ``partial 5x4``).
"""

import argparse
import gc
import os
import sys
import time
from typing import Dict, List, Sequence, Tuple

for _var in ('OMP_NUM_THREADS', 'OPENBLAS_NUM_THREADS', 'MKL_NUM_THREADS',
             'NUMEXPR_NUM_THREADS', 'VECLIB_MAXIMUM_THREADS'):
    os.environ[_var] = '1'

import numpy as np  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
DATA = os.path.join(ROOT, '..', 'shared', 'data')
CONFIGS = ((4, 2), (5, 4), (16, 6))
CASES = ('complete', 'partial', 'pose2sim', 'shelf')
# Reference code (Tanke & Gall, published implementation) measured on a 2-core CPU, from the
# project issue: 55-79 ms per frame at 5 cameras x 4 people, 1.6 s at 16 x 6.
REFERENCE_MS = {'complete 5x4': '55-79', 'complete 16x6': '1600'}
WARM_UP = 5                 # frames not timed: imports, caches, track births
#: The step's own CPU time (``cpu``: what it costs, unaffected by time other processes take on
#: a shared machine) or the time that passed (``wall``).
CLOCKS = {'cpu': time.thread_time, 'wall': time.perf_counter}


def _pin_one_core() -> str:
    try:
        cpu = sorted(os.sched_getaffinity(0))[0]
        os.sched_setaffinity(0, {cpu})
        return f'pinned to CPU {cpu}'
    except (AttributeError, OSError):
        return 'not pinned (no sched_setaffinity)'


# ---------------------------------------------------------------------------- inputs
def _synthetic(cams: int, people: int, frames: int, partial: bool, seed: int = 0) -> dict:
    from mv3dpose_ros.sim.people import WalkConfig
    from mv3dpose_ros.sim.rig import RigConfig
    from mv3dpose_ros.sim.scene import make_scene
    # Bigger crowds need a bigger floor; in the complete case the people stay inside the views.
    radius = 6.0 if people <= 8 else 9.0
    if partial:             # 50 degree lenses, people out to 80 % of the rig's radius
        rig, walk = RigConfig(num_cameras=cams, radius_m=radius, hfov_deg=50.0), \
            WalkConfig(area_radius_m=radius * 0.8)
    else:
        rig, walk = RigConfig(num_cameras=cams, radius_m=radius), \
            WalkConfig(area_radius_m=radius * 0.5)
    scene = make_scene(num_cameras=cams, num_people=people, num_frames=frames, fps=25.0,
                       layout='coco17', seed=seed, rig=rig, walk=walk)
    return _case(scene.cameras, scene.layout, list(scene.frames()))


def _pose2sim(frames: int) -> dict:
    from mv3dpose_ros.core.geometry.calibration import load_calibration
    from mv3dpose_ros.io.openpose import match_camera_folders, OpenPoseSequence
    folder = os.path.join(DATA, 'pose2sim_multiperson')
    cams = load_calibration(os.path.join(folder, 'Calib_qualisys.toml'))
    found, _ = match_camera_folders(os.path.join(folder, 'pose'), list(cams))
    seq = OpenPoseSequence(found, 25)
    return _case(cams, 'body25b', [(f / 60.0, seq.read(f)) for f in seq.frames[:frames]])


def _shelf(frames: int, people: int = 4, seed: int = 1) -> dict:
    # test_calibrate.shelf_proxy's scene: slow walkers around the shelf, a real detector's errors
    from mv3dpose_ros.core.geometry.calibration import load_calibration
    from mv3dpose_ros.sim.detector import detect, DetectorNoise
    from mv3dpose_ros.sim.people import simulate_people, WalkConfig
    cams = load_calibration(os.path.join(DATA, 'shelf', 'calibration_shelf.json'))
    walk = WalkConfig(area_radius_m=1.4, center=(0.45, -0.3), speed_range_mps=(0.3, 1.0),
                      min_separation_m=0.6)
    gt, _, _ = simulate_people(people, frames, 25.0, 'coco17', walk, None,
                               np.random.default_rng(seed))
    noise = DetectorNoise(pixel_noise_px=3.0, relative_noise=0.01, joint_miss_rate=0.05,
                          person_miss_rate=0.05, false_positive_rate=0.1, swap_rate=0.03,
                          outlier_rate=0.02, outlier_px=60.0)
    views, _ = detect(cams, gt, 'coco17', noise, seed=seed + 1)
    return _case(cams, 'coco17', [(f / 25.0, v) for f, v in enumerate(views)])


def _case(cameras, layout: str, frames: list) -> dict:
    """Return a case as plain data, so a tree of another version can rebuild it."""
    cams = [{'name': c.name, 'K': c.K, 'dist': c.dist, 'R': c.R, 't': c.t, 'width': c.width,
             'height': c.height} for c in cameras.values()]
    return {'cameras': cams, 'layout': layout, 'frames': frames}


def build_cases(cases: Sequence[str], configs, frames: int) -> Dict[str, dict]:
    """Return the inputs of every case, by its printed name."""
    out = {}
    for case in cases:
        if case in ('complete', 'partial'):
            for c, p in configs:
                out[f'{case} {c}x{p}'] = _synthetic(c, p, frames, case == 'partial')
        elif case == 'pose2sim':
            if os.path.isdir(os.path.join(DATA, 'pose2sim_multiperson')):
                out[case] = _pose2sim(frames)
            else:
                print(f'pose2sim: no data under {DATA}, skipped', file=sys.stderr)
        elif case == 'shelf':
            if os.path.isfile(os.path.join(DATA, 'shelf', 'calibration_shelf.json')):
                out[case] = _shelf(frames)
            else:
                print(f'shelf: no Shelf rig under {DATA}, skipped', file=sys.stderr)
        else:
            raise SystemExit(f'unknown case {case!r} (known: {", ".join(CASES)})')
    return out


# ---------------------------------------------------------------------------- timing
def _fusion_class():
    """Return ``(Fusion, Camera)`` of the tree on the path (stage packages or the flat core)."""
    try:
        from mv3dpose_ros.core.fusion.pipeline import Fusion
        from mv3dpose_ros.core.geometry.camera import Camera
    except ImportError:         # before core/ was one package per stage
        from mv3dpose_ros.core.camera import Camera
        from mv3dpose_ros.core.fusion import Fusion
    return Fusion, Camera


def load_tree(tree: str):
    """
    Return ``(Fusion, Camera)`` of the package in source tree ``tree``, beside this one's.

    The tree's modules are imported under their own names and then taken out of
    ``sys.modules`` again (the fusion core imports nothing at call time), so several versions
    of the package run in one process.
    """
    ours = {k: m for k, m in sys.modules.items() if k.split('.')[0] == 'mv3dpose_ros'}
    for k in ours:
        del sys.modules[k]
    sys.path.insert(0, tree)
    try:
        classes = _fusion_class()
    finally:
        sys.path.remove(tree)
        for k in [k for k in sys.modules if k.split('.')[0] == 'mv3dpose_ros']:
            del sys.modules[k]
        sys.modules.update(ours)
    return classes


def time_cases(cases: Dict[str, dict], trees: Sequence, repeat: int, clock: str = 'cpu'
               ) -> Dict[str, List[np.ndarray]]:
    """
    Return ``{case: [times [runs, frames] ms per tree]}``, the trees stepped in turn.

    ``trees`` are ``(Fusion, Camera)`` classes; each run makes a fresh ``Fusion`` per tree and
    steps every frame through each of them before the next frame (the first tree first on
    even frames, last on odd ones), warm-up frames left out.
    """
    now = CLOCKS[clock]
    out = {}
    for name, case in cases.items():
        times = np.zeros((len(trees), repeat, len(case['frames'])))
        cams = [{c['name']: camera_cls(**c) for c in case['cameras']}
                for _, camera_cls in trees]
        for r in range(repeat):
            fusions = [fusion_cls(cams[k], case['layout'])
                       for k, (fusion_cls, _) in enumerate(trees)]
            gc.collect()
            for f, (stamp, views) in enumerate(case['frames']):
                for k in range(len(trees)) if f % 2 == 0 else reversed(range(len(trees))):
                    t0 = now()
                    fusions[k].step(views, stamp)
                    times[k, r, f] = 1e3 * (now() - t0)
        out[name] = [t[:, WARM_UP:] for t in times]
    return out


def summary(times: np.ndarray) -> Tuple[float, float]:
    """
    Return ``(floor, median)`` [ms] of ``times [runs, frames]``.

    ``floor``: the median over frames of each frame's fastest run, the figure least moved by
    other processes on a shared machine; ``median``: the median of the runs' medians.
    """
    return float(np.median(times.min(axis=0))), float(np.median(np.median(times, axis=1)))


def _profile(case: dict, name: str) -> int:
    import cProfile
    import pstats
    fusion_cls, camera_cls = load_tree(ROOT)
    fusion = fusion_cls({c['name']: camera_cls(**c) for c in case['cameras']}, case['layout'])
    prof = cProfile.Profile()
    prof.enable()
    for stamp, views in case['frames']:
        fusion.step(views, stamp)
    prof.disable()
    print(f'{name}: {len(case["frames"])} frames')
    pstats.Stats(prof).sort_stats('cumulative').print_stats(30)
    return 0


def main() -> int:
    """Print the benchmark table."""
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[1])
    parser.add_argument('--cases', default=','.join(CASES), help='comma-separated cases')
    parser.add_argument('--configs', default=','.join(f'{c}x{p}' for c, p in CONFIGS),
                        help='comma-separated CAMERASxPEOPLE of the synthetic cases')
    parser.add_argument('--frames', type=int, default=100, help='frames per case')
    parser.add_argument('--repeat', type=int, default=5, help='runs per case')
    parser.add_argument('--against', default='',
                        help='comma-separated source trees to time the same inputs with')
    parser.add_argument('--clock', choices=sorted(CLOCKS), default='cpu',
                        help='CPU time of the step (default) or wall time')
    parser.add_argument('--profile', default='', help='a case to profile (cProfile)')
    args = parser.parse_args()
    configs = [tuple(int(v) for v in c.split('x')) for c in args.configs.split(',') if c]
    cases = build_cases([c for c in args.cases.split(',') if c], configs, args.frames)
    if args.profile:
        return _profile(cases[args.profile], args.profile)
    paths = [ROOT] + [os.path.abspath(t) for t in args.against.split(',') if t]
    trees = [load_tree(t) for t in paths]
    pin = _pin_one_core()
    print(f'Fusion.step, one core ({pin}), {args.clock} ms per set after {WARM_UP} warm-up '
          f'frames, {args.frames} frames per case, {args.repeat} runs, numpy {np.__version__}')
    for k, path in enumerate(paths):
        print(f'  [{k}] {path}')
    times = time_cases(cases, trees, args.repeat, args.clock)
    head = ''.join(f'{f"[{k}] floor":>11} {"median":>7}' for k in range(len(trees)))
    head += ''.join(f'{f"[0]/[{k}]":>8}' for k in range(1, len(trees)))
    print(f'{"case":>14}{head} {"reference ms":>13}')
    for name in cases:
        t = times[name]
        cells = ''.join(f'{floor:11.3f} {median:7.3f}' for floor, median in map(summary, t))
        cells += ''.join(f'{np.median(t[0] / t[k]):8.3f}' for k in range(1, len(trees)))
        print(f'{name:>14}{cells} {REFERENCE_MS.get(name, "-"):>13}', flush=True)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
