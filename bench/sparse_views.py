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
Sparse views: the live output when camera-frames are missing or late, set-based vs per-camera.

Replays detections at a live rate with every camera-frame dropped independently at random
(``--drops``; one seeded mask per seed, the same for both paths, nested across rates) and
prints, per data set and drop rate, the live output (``LiveOutput.step`` over ``Fusion.step``
as ``mv3dpose track --smooth causal`` / fusion_node ``~/tracks``) of the set-based path
(``FusionConfig.view_updates=False``: only joints triangulated from >= 2 views of one set) next
to the per-camera path (``view_updates=True``: 2D updates of existing tracks from single views).

Data: Pose2Sim multiperson real OpenPose BODY_25B detections (every 5th frame of 60 fps = 12
Hz; 5 phases, no GT); Campus GT through the simulated detector (``sim.detector.detect``) at
``--noise`` scales, the test frames 350-470 and 650-750 replayed one segment at a time (fresh
tracker each), taking alternately every 2nd and 3rd frame (10 Hz mean, stamped at their real
capture time); Panoptic band1 GT (20 frames at 30 fps, every 3rd = 10 Hz, 3 phases) in 5 and
10 HD cameras; a synthetic 5-camera rig of 4 people walking for 20 s at 10 Hz (``sim``; long
enough that births do not dominate, as they do in the 7-set Panoptic runs). Without
``--delays`` every frame is stepped with the views it kept (none: an empty set), as
``mv3dpose track`` steps a frame with missing files.

``--delays``: each message arrives capture + 30 ms + camera index x 40 ms + jitter (exp.,
mean 15 ms; 5 % stalls of 0.2-0.6 s), replayed in arrival order through the real
``StreamSynchronizer`` (add / poll on its next decision time, as fusion_node does), with
fusion_node's ``min_views`` (``SyncConfig``'s default with view updates, at least 2 without).
Late messages go to ``Fusion.update_view`` in the per-camera path and are dropped in the
set-based one (``late``: late messages, ``used``: those that updated a track, ``sets``: sets
emitted). A frame without a set is scored with the last published output (what a consumer
shows then); a set of messages of different capture stamps is scored at the nearest frame.

Columns: ``ids`` distinct confirmed ids, ``ret`` ids that vanished and came back, ``dup%``
confirmed skeletons with another within 0.3 m, ``reproj`` median px from published skeletons
to the nearest detection in every camera (dropped views included), ``org`` / ``nan`` published
roots at (0,0,0) / non-finite (totals), ``sw/m`` ID switches per minute, ``frag``
fragmentations; the rest (means over seeds and phases) as ``mv3dpose eval``. Figures, never
assertions::

    python bench/sparse_views.py [--data pose2sim,campus,panoptic] [--drops 0,0.2,0.4]
        [--seeds 1,2,3] [--noise 1,2] [--delays] [--quick]
"""

import argparse
import dataclasses
import functools
import os
import sys
from typing import Callable, Dict, List, Optional

from mv3dpose_ros.core.fusion.pipeline import Fusion, FusionConfig
from mv3dpose_ros.core.geometry.calibration import load_calibration
from mv3dpose_ros.core.live.output import LiveOutput
from mv3dpose_ros.core.live.sync import StreamSynchronizer, SyncConfig
from mv3dpose_ros.core.types import TrackState
from mv3dpose_ros.eval.sequence import evaluate_run, GroundTruth, load_ground_truth
from mv3dpose_ros.io.datasets import load_panoptic_gt
from mv3dpose_ros.io.openpose import match_camera_folders, OpenPoseSequence
from mv3dpose_ros.sim.detector import detect, DetectorNoise
from mv3dpose_ros.sim.scene import make_scene
import numpy as np

try:
    from mv3dpose_ros.eval.identity import duplicate_rate, identity_summary
except ImportError:     # LOCAL until eval's identity metrics land: replace with those
    from mv3dpose_ros.eval.mpjpe import pose_distances
    identity_summary = None

    def duplicate_rate(frames, radius_m: float = 0.3) -> float:
        """Share of confirmed skeletons with another one of its message within ``radius_m``."""
        total = dup = 0
        for _, skeletons in frames:
            total += len(skeletons)
            if len(skeletons) > 1:
                poses = np.array([p for _, p in skeletons])
                d = pose_distances(poses, poses) + np.diag(np.full(len(poses), np.inf))
                dup += int((d < radius_m).any(1).sum())
        return dup / total if total else float('nan')

DATA = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), '..',
                    'shared', 'data')
# Older trees (A/B runs) may lack single-view updates: then only the set-based path runs.
VIEW_UPDATES = 'view_updates' in {f.name for f in dataclasses.fields(FusionConfig)}
UPDATE_VIEW = hasattr(Fusion, 'update_view')
PANOPTIC_CAMS = ['00_03', '00_06', '00_12', '00_13', '00_23', '00_00', '00_09', '00_16',
                 '00_19', '00_28']
T0_S = 1.0                  # stamps start here (the synchroniser takes only stamps > 0)
DUPLICATE_M = 0.3           # two confirmed skeletons closer than this: one person twice
MIN_RELEASE_S = 0.001       # the node's release timer fires no sooner than this
CAMPUS_SEGMENTS = ((350, 470), (650, 750))      # the test frames, replayed one at a time
PATHS = ('set-based', 'per-camera')


@dataclasses.dataclass
class Replay:
    """One replayed sequence: full detections per frame (before any drop) and ground truth."""

    cameras: dict
    layout: str
    fps: float
    frames: List[int]
    views: List[Dict[str, np.ndarray]]
    gt: Optional[GroundTruth] = None
    eval_frames: Optional[List[int]] = None

    def stamp_ns(self, frame: int) -> int:
        """Return the capture stamp of ``frame``."""
        return int(round((T0_S + frame / self.fps) * 1e9))


@functools.lru_cache(maxsize=None)
def _pose2sim_all():
    folder = os.path.join(DATA, 'pose2sim_multiperson')
    cams = load_calibration(os.path.join(folder, 'Calib_qualisys.toml'))
    found, _ = match_camera_folders(os.path.join(folder, 'pose'), list(cams))
    seq = OpenPoseSequence(found, 25)
    return cams, seq.frames, [seq.read(f) for f in seq.frames]


def pose2sim(phase: int) -> Replay:
    """Return Pose2Sim's real detections, every 5th frame from ``phase`` (12 Hz)."""
    cams, frames, views = _pose2sim_all()
    return Replay(cams, 'body25b', 60.0, frames[phase::5], views[phase::5])


@functools.lru_cache(maxsize=None)
def _gt(name: str):
    if name == 'campus':
        folder = os.path.join(DATA, 'campus')
        return (load_calibration(os.path.join(folder, 'calibration_campus.json')),
                load_ground_truth(folder, 'campus'), None)
    folder = os.path.join(DATA, 'panoptic_160906_band1')
    return (load_calibration(os.path.join(folder, 'calibration_160906_band1.json'),
                             cameras=PANOPTIC_CAMS), load_ground_truth(folder, 'panoptic'),
            load_panoptic_gt(os.path.join(folder, 'hdPose3d_stage1_coco19')).as_array()[1])


def campus(noise: float, seed: int, first: int, last: int, quick: bool) -> Replay:
    """Return Campus frames first..last every 2nd / 3rd frame through the simulated detector."""
    cams, gt, _ = _gt('campus')
    frames = [int(f) for f in first + np.cumsum([0] + [2, 3] * 50) if f <= last]
    frames = frames[:20] if quick else frames
    poses = np.full((len(frames), 3, 14, 3), np.nan)
    for k, f in enumerate(frames):
        ids, p = gt.frames[f]
        poses[k, ids] = p
    views, _ = detect(cams, poses, 'shelf14', DetectorNoise().scaled(noise), seed=seed)
    return Replay(cams, 'shelf14', 25.0, frames, views, gt, frames)


def synthetic(noise: float, seed: int, frames: int) -> Replay:
    """Return a synthetic 5-camera rig of 4 walking people at 10 Hz (``mv3dpose_ros.sim``)."""
    scene = make_scene(num_cameras=5, num_people=4, num_frames=frames, fps=10.0, seed=seed,
                       noise=DetectorNoise().scaled(noise))
    ids = np.arange(scene.num_people)
    gt = GroundTruth(scene.layout, {f: (ids, scene.gt[f]) for f in range(frames)})
    return Replay(scene.cameras, scene.layout, 10.0, list(range(frames)), list(scene.views),
                  gt, list(range(frames)))


def panoptic(num_cams: int, noise: float, seed: int, phase: int) -> Replay:
    """Return Panoptic band1 every 3rd frame from ``phase`` in ``num_cams`` HD cameras."""
    all_cams, gt, poses = _gt('panoptic')
    cams = {n: all_cams[n] for n in PANOPTIC_CAMS[:num_cams]}
    index = list(range(phase, len(gt.frames), 3))
    frames = [sorted(gt.frames)[i] for i in index]
    views, _ = detect(cams, poses[index, ..., :3], 'panoptic19',
                      DetectorNoise().scaled(noise), seed=seed)
    return Replay(cams, 'panoptic19', 30.0, frames, views, gt, frames)


def replay_drops(rep: Replay, keep: np.ndarray, step: Callable) -> dict:
    """Step every frame with the views kept (an all-dropped frame is an empty set)."""
    names = list(rep.cameras)
    for k, f in enumerate(rep.frames):
        step({c: rep.views[k][c] for i, c in enumerate(names) if keep[k, i]},
             rep.stamp_ns(f), f)
    return {}


def replay_delays(rep: Replay, keep: np.ndarray, step: Callable, late: Callable,
                  arrival: np.ndarray, per_camera: bool) -> dict:
    """Feed the kept messages through ``StreamSynchronizer`` in arrival order."""
    names = list(rep.cameras)
    stamps = np.array([rep.stamp_ns(f) for f in rep.frames])
    views = SyncConfig().min_views            # as fusion_node: 2 without view updates
    sync = StreamSynchronizer(names, SyncConfig(min_views=views if per_camera else max(2, views)))
    events = sorted((int(arrival[k, i]), i, k) for k in range(len(rep.frames))
                    for i in range(len(names)) if keep[k, i])
    counts = {'sets': 0, 'mixed': 0, 'late': 0, 'used': 0}

    def release(sets):
        for s in sets:
            counts['sets'] += 1
            # a set of messages of different capture times is scored at the nearest frame
            counts['mixed'] += len(set(s.stamps_ns.values())) > 1
            step(s.messages, s.stamp_ns, rep.frames[np.abs(stamps - s.stamp_ns).argmin()])

    def timer(until):          # the node's release timer, armed on next_decision_ns
        nonlocal now
        while sync.pending():
            due = sync.next_decision_ns(now)
            due = max(due, now + int(MIN_RELEASE_S * 1e9)) if due is not None else None
            if due is None or due >= until:
                return
            now = due
            release(sync.poll(now))

    now = events[0][0] if events else 0
    for t, i, k in events:
        timer(t)
        now, stamp = t, int(stamps[k])
        poses = rep.views[k][names[i]]
        res = sync.add(names[i], stamp, poses, now)
        if res.kind == 'late':
            counts['late'] += 1
            counts['used'] += int(late(names[i], poses, stamp) > 0)
        release(res.sets)
        release(sync.poll(now))
    timer(now + 10 ** 10)
    release(sync.flush())
    return counts


def arrivals(rep: Replay, seed: int) -> np.ndarray:
    """Return ``[F, C]`` arrival times [ns]: 30 ms + camera x 40 ms + jitter and stalls."""
    rng = np.random.default_rng([seed, 25, rep.frames[0]])
    shape = (len(rep.frames), len(rep.cameras))
    delay = 0.030 + 0.040 * np.arange(shape[1]) + rng.exponential(0.015, shape)
    delay += np.where(rng.random(shape) < 0.05, rng.uniform(0.2, 0.6, shape), 0.0)
    return np.array([rep.stamp_ns(f) for f in rep.frames])[:, None] + (delay * 1e9).astype(int)


def run(rep: Replay, keep: np.ndarray, per_camera: bool,
        arrival: Optional[np.ndarray] = None) -> dict:
    """Replay one sequence through one path; return its figures."""
    extra = {'view_updates': per_camera} if VIEW_UPDATES else {}
    fusion = Fusion(rep.cameras, rep.layout, FusionConfig(smoothing='causal', **extra))
    output = LiveOutput(fusion.config.publish_coast_s, root_joints=fusion.layout.root_joints)
    num_j = fusion.layout.num_joints
    hyps, stamps, messages, roots, reproj = {}, {}, [], [], []

    def step(views, stamp_ns, frame):
        stamp = stamp_ns / 1e9
        tracks, _ = output.step(fusion.step(views, stamp, stamp_ns), stamp, frame)
        tracks = [t for t in tracks if t.state != TrackState.DELETED]
        hyps[frame] = (np.array([t.track_id for t in tracks], dtype=int),
                       np.array([t.joints for t in tracks]).reshape(len(tracks), num_j, 3))
        stamps[frame] = stamp
        confirmed = [(t.track_id, t.joints) for t in tracks if t.state == TrackState.CONFIRMED]
        messages.append((stamp, confirmed))
        roots.extend(t.position for t in tracks)
        if rep.gt is None:
            full = rep.views[rep.frames.index(frame)]
            reproj.extend(_reprojection(rep.cameras, full, [j for _, j in confirmed]))

    def late(camera, poses, stamp_ns):
        if per_camera and UPDATE_VIEW:
            return fusion.update_view(camera, poses, stamp_ns / 1e9, stamp_ns)
        return 0

    counts = (replay_delays(rep, keep, step, late, arrival, per_camera) if arrival is not None
              else replay_drops(rep, keep, step))
    for prev, f in zip(rep.frames, rep.frames[1:]):    # no set: the consumer holds the last
        if f not in hyps and prev in hyps:
            hyps[f], stamps[f] = hyps[prev], stamps[prev] + (f - prev) / rep.fps
    roots = np.array(roots).reshape(-1, 3)
    out = dict(counts, ids=len({i for _, sk in messages for i, _ in sk}),
               zero=int((roots == 0).all(1).sum()), nan=int((~np.isfinite(roots)).any(1).sum()),
               dup=100 * duplicate_rate(messages, DUPLICATE_M))
    if rep.gt is None:
        out['reproj'] = float(np.median(reproj)) if reproj else float('nan')
        out['ret'] = identity_summary(messages, 2).returns if identity_summary else np.nan
        return out
    try:
        r = evaluate_run(rep.layout, hyps, rep.gt, frames=rep.eval_frames, stamps=stamps)
    except TypeError:       # eval without stamps (identity metrics not landed yet)
        r = evaluate_run(rep.layout, hyps, rep.gt, frames=rep.eval_frames)
    m = r.mot
    return dict(out, pcp=100 * r.pcp.average, mota=100 * m.mota, mpjpe=1000 * r.mpjpe.mpjpe_m,
                idsw=m.id_switches, idf1=100 * m.idf1, frag=m.fragmentations,
                swpm=getattr(m, 'id_switches_per_min', np.nan))


def _reprojection(cameras: dict, views: dict, skeletons: list) -> List[float]:
    """
    Return, per (skeleton, camera), the median px distance to its nearest full detection.

    All detections count, dropped and late ones included (held-out views); a detection is
    the skeleton's when its median joint distance is under a tenth of the image height.
    """
    out = []
    for name, cam in cameras.items():
        det = views.get(name)
        if det is None or not len(det):
            continue
        for joints in skeletons:
            d = np.linalg.norm(det[..., :2] - cam.project(joints)[None], axis=-1)
            d = np.where(det[..., 2] > 0.1, d, np.nan)
            enough = np.isfinite(d).sum(axis=1) >= 3
            if enough.any():
                best = np.nanmedian(d[enough], axis=1).min()
                if best < 0.1 * cam.height:
                    out.append(float(best))
    return out


GT_COLS = (('PCP', 'pcp', 5, 1), ('MOTA', 'mota', 5, 1), ('MPJPE', 'mpjpe', 5, 1),
           ('sw/m', 'swpm', 5, 1), ('IDF1', 'idf1', 5, 1), ('frag', 'frag', 4, 1),
           ('ids', 'ids', 4, 1), ('org', 'zero', 3, 0), ('nan', 'nan', 3, 0),
           ('dup%', 'dup', 4, 1))
NOGT_COLS = (('ids', 'ids', 4, 1), ('ret', 'ret', 4, 1), ('org', 'zero', 3, 0),
             ('nan', 'nan', 3, 0), ('dup%', 'dup', 4, 1), ('reproj', 'reproj', 6, 1))
DELAY_COLS = (('sets', 'sets', 5, 1), ('late', 'late', 4, 1), ('used', 'used', 4, 1))


def table(title: str, variants: Dict[str, Callable], drops: List[float], seeds: List[int],
          delays: bool, has_gt: bool) -> None:
    """Run every variant x drop rate x seed x phase and print one table."""
    cols = (GT_COLS if has_gt else NOGT_COLS) + (DELAY_COLS if delays else ())
    paths = [p for p in (False, True) if p is False or VIEW_UPDATES]
    group = ' '.join(f'{h:>{w}}' for h, _, w, _ in cols)
    width = len(group)
    lead = f'{"":<12} {"drop":>4}'
    print(f'\n{title}')
    print(' ' * len(lead) + ' | ' + ' | '.join(f'{PATHS[p]:^{width}}' for p in (0, 1)))
    print(lead + ' | ' + ' | '.join([group] * 2))
    mixed = 0
    for name, make in variants.items():
        for drop in drops:
            rows: Dict[bool, list] = {p: [] for p in paths}
            for seed in seeds:
                for j, rep in enumerate(make(seed)):
                    mask = np.random.default_rng([seed, 7, j]).random(
                        (len(rep.frames), len(rep.cameras)))
                    keep = mask >= drop
                    arrival = arrivals(rep, seed) if delays else None
                    for p in paths:
                        rows[p].append(run(rep, keep, p, arrival))
            print(f'  {title.split()[0]} {name} drop {drop:g}: {len(rows[False])} runs',
                  file=sys.stderr)
            mean = {p: {k: _mean([r[k] for r in v], total=k in ('zero', 'nan'))
                        for k in v[0]} for p, v in rows.items()}
            head = f'{name:<12} {drop:>4g}'
            mixed += sum(r.get('mixed', 0) for v in rows.values() for r in v)
            cells = [' '.join(f'{mean[p][k]:>{w}.{d}f}' for _, k, w, d in cols)
                     if p in mean else f'{"n/a (no FusionConfig.view_updates yet)":^{width}}'
                     for p in (False, True)]
            print(head + ' | ' + ' | '.join(cells), flush=True)
    if mixed:
        print(f'note: {mixed} sets held messages of different capture stamps (scored at the '
              'nearest frame)')


def _mean(values: list, total: bool = False) -> float:
    """Return the mean of the finite values (NaN if none), or their sum with ``total``."""
    v = np.array(values, dtype=float)
    v = v[np.isfinite(v)]
    return float(v.sum() if total else v.mean()) if v.size else float('nan')


def main(argv: Optional[List[str]] = None) -> int:
    """Parse the arguments and print one table per data set."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--data', default='pose2sim,campus,panoptic,synthetic')
    parser.add_argument('--drops', default='0,0.2,0.4', help='camera-frame drop rates')
    parser.add_argument('--seeds', default='1,2,3', help='drop mask / detector / delay seeds')
    parser.add_argument('--noise', default='1,2', help='detector noise scales (Campus, Panoptic)')
    parser.add_argument('--delays', action='store_true',
                        help='per-camera delays through StreamSynchronizer (late messages)')
    parser.add_argument('--quick', action='store_true',
                        help='a short smoke run: one phase, 20 Campus sets, 5 Panoptic cams')
    args = parser.parse_args(argv)
    if not os.path.isdir(DATA):
        print(f'no data at {DATA}', file=sys.stderr)
        return 1
    data = args.data.split(',')
    drops = [float(x) for x in args.drops.split(',')]
    seeds = [int(x) for x in args.seeds.split(',')]
    noise = [float(x) for x in args.noise.split(',')]
    q = args.quick
    print(f'sparse views: drop rates {drops}, seeds {seeds}, '
          f'{"delays through StreamSynchronizer" if args.delays else "no delays"}; '
          f'FusionConfig.view_updates {"present" if VIEW_UPDATES else "ABSENT"}, '
          f'Fusion.update_view {"present" if UPDATE_VIEW else "ABSENT"}')
    if 'pose2sim' in data:
        table('Pose2Sim multiperson (real OpenPose, 4 cams, 12 Hz, no GT)',
              {'real': lambda s: [pose2sim(p) for p in range(1 if q else 5)]},
              drops, seeds, args.delays, has_gt=False)
    if 'campus' in data:
        table('Campus (3 cams, simulated detector, 10 Hz)',
              {f'noise x{n:g}': functools.partial(
                  lambda s, n: [campus(n, s, a, b, q) for a, b in CAMPUS_SEGMENTS], n=n)
               for n in noise}, drops, seeds, args.delays, has_gt=True)
    if 'panoptic' in data:
        table('Panoptic band1 (HD cams, simulated detector, 10 Hz)',
              {f'{c}c x{n:g}': functools.partial(
                  lambda s, c, n: [panoptic(c, n, s, p) for p in range(1 if q else 3)], c=c, n=n)
               for c in ((5,) if q else (5, 10)) for n in noise}, drops, seeds, args.delays,
              has_gt=True)
    if 'synthetic' in data:
        table('Synthetic (5 cams x 4 people walking, simulated detector, 10 Hz, 20 s)',
              {f'noise x{n:g}': functools.partial(
                  lambda s, n: [synthetic(n, s, 50 if q else 200)], n=n) for n in noise},
              drops, seeds, args.delays, has_gt=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
