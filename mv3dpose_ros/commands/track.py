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
``mv3dpose track``: 3D tracks from per-camera OpenPose JSON folders, offline.

Input: a calibration file (any format ``core.geometry.calibration`` reads) and a folder ``ROOT``
with one sub-folder of OpenPose JSON files per camera, named like the camera (loosely: Pose2Sim's
``cam01_json`` is camera ``cam_01``). Frames are matched across cameras by the number in the
file names; frame ``n`` gets the stamp ``n / fps`` seconds (``round(n * 1e9 / fps)`` ns).
Every frame goes through ``Fusion.step``, the very code the live ``fusion_node`` runs. Under
``--smooth causal`` and ``fixed-lag`` each frame is one set of the node's own live core
(``core.live.loop.LiveFusion``: ``Fusion.step``, coasting, the publication rules of
``core.live.output``), so ``--smooth causal`` writes exactly what ``fusion_node`` publishes on
``~/tracks``, and ``--smooth fixed-lag --lag-frames L`` exactly what it publishes on
``~/tracks_smoothed`` with ``smoothed_lag_frames: L``
(``core.tracking.smoothing.FixedLagSmoother``; each frame is written with its own number and stamp,
and the last L frames, which the node publishes once L more sets, its idle steps after the
input stops or a reset come, are flushed at the end).
``--smooth none`` writes every track ``Fusion.step`` keeps (internal ids, tentative ones too)
with the accepted raw triangulations. ``--smooth offline`` (the default for this batch command,
as in the paper) takes the accepted raw triangulations (not the filtered joints) and applies
the paper's Gaussian smoothing to whole tracks (``core.tracking.smoothing.smooth_track_sequence``)
after settling the run with hindsight (``core.tracking.hindsight.settle_tracks``: fragments of one
person linked into one id, tracks confirmed from their first frame, ghosts and predictions
after a person's last observation dropped).

Output: JSON Lines, one line per frame (``io.tracks_jsonl``), with one DELETED tombstone per
ended track; consumers pick the states they want. The file is written to a temporary file
beside it and renamed into place only when the run succeeds. Exit status: 0 done, 1 cannot
write, 2 bad arguments or unreadable calibration / folders, 3 done but malformed pose files
were skipped (each named on stderr).
"""

import argparse
import contextlib
import dataclasses
import logging
import os
import sys
import time
from typing import Iterator, Tuple

from mv3dpose_ros.io.pose_inputs import add_image_size_argument, open_inputs

LOG = logging.getLogger('mv3dpose.track')
SMOOTH_MODES = ('causal', 'fixed-lag', 'offline', 'none')


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``mv3dpose track``."""
    parser.add_argument('--calibration', required=True, metavar='FILE',
                        help='camera calibration (rig YAML, Panoptic/VoxelPose JSON, '
                             'Pose2Sim TOML)')
    parser.add_argument('--calibration-format', default='auto',
                        help='calibration format (default: auto-detect)')
    add_image_size_argument(parser)
    parser.add_argument('--poses', required=True, metavar='ROOT',
                        help='folder with one OpenPose JSON folder per camera')
    parser.add_argument('--layout', required=True,
                        help='joint layout of the detections: coco17, body25, body25b, ...')
    parser.add_argument('--output', '-o', required=True, metavar='FILE',
                        help="tracks JSON Lines file ('-' = standard output)")
    parser.add_argument('--fps', type=float, default=30.0,
                        help='frame rate: frame n has stamp n / fps seconds (default 30)')
    parser.add_argument('--smooth', choices=SMOOTH_MODES, default='offline',
                        help="offline (default): the paper's Gaussian smoothing of whole "
                             'tracks and states settled with hindsight; causal: the live '
                             "output, identical to fusion_node's ~/tracks; fixed-lag: "
                             'identical to its ~/tracks_smoothed (see --lag-frames); none: '
                             'accepted raw triangulations of every track kept')
    parser.add_argument('--lag-frames', type=int, default=3,
                        help='lag of --smooth fixed-lag in frames (the smoothed_lag_frames '
                             'of fusion_node; default 3)')
    parser.add_argument('--sigma-frames', type=float, default=2.0,
                        help='Gaussian sigma in frames for --smooth offline (paper: 2)')
    parser.add_argument('--max-gap-frames', type=int, default=10,
                        help='gaps filled by interpolation for --smooth offline')
    parser.add_argument('--cameras', nargs='+', metavar='NAME',
                        help='use only these calibrated cameras (default: all with a folder)')
    parser.add_argument('--params', metavar='YAML',
                        help='FusionConfig fields: a flat mapping, or a ROS parameter file '
                             '(its fusion: section, e.g. config/fusion.yaml)')
    parser.add_argument('--save-rig', metavar='PATH',
                        help='write the rig in use at the end as a rig YAML (with the '
                             "calibration watch's corrections, fusion.calibration_watch)")
    parser.add_argument('--no-progress', action='store_true', help='no progress bar')


def load_fusion_params(path: str) -> dict:
    """
    Read FusionConfig fields from YAML: a flat mapping or a ROS 2 parameter file.

    In a parameter file the first ``ros__parameters`` section with a ``fusion`` mapping is
    used. Unknown field names raise ValueError naming them and the file.
    """
    from mv3dpose_ros.core.fusion.pipeline import FusionConfig
    from mv3dpose_ros.io.params_file import first_section_with, read_params_file

    data = read_params_file(path)
    if not isinstance(data, dict):
        raise ValueError(f'{path}: expected a mapping of FusionConfig fields')
    params = first_section_with(data, 'fusion')
    if params is None:
        params = data
    known = {f.name for f in dataclasses.fields(FusionConfig)}
    unknown = sorted(str(k) for k in set(params) - known)
    if unknown:
        raise ValueError(f'{path}: unknown FusionConfig field(s) {unknown}; '
                         f'known: {sorted(known)}')
    try:
        FusionConfig(**params).validate()      # wrong types and ranges, named with the file
    except (TypeError, ValueError) as e:
        raise ValueError(f'{path}: {e}') from None
    return dict(params)


@contextlib.contextmanager
def _progress(total: int, progress: bool):
    """Yield a callable that advances a tqdm bar on stderr (a no-op without ``progress``)."""
    if not progress:
        yield lambda: None
        return
    from tqdm import tqdm
    bar = tqdm(total=total, unit='frame', desc='tracking', file=sys.stderr)
    try:
        yield lambda: bar.update(1)
    finally:
        bar.close()


def run_fusion(fusion, watch, seq, fps: float, progress: bool = False
               ) -> Iterator[Tuple[int, float, list]]:
    """
    Yield ``(frame, stamp, tracks)`` for every frame of ``seq`` through ``fusion.step``.

    Frame ``n`` is stamped ``n / fps`` s, exactly ``round(n * 1e9 / fps)`` ns in the tracks.
    ``watch`` (``core.selfcal.watch.CalibrationWatch``) checks the rig set by set, as the live
    core does; what it finds is logged as there.
    """
    with _progress(len(seq.frames), progress) as tick:
        for frame in seq.frames:
            stamp = frame / fps
            tracks, events = watch.fused(fusion, seq.read(frame), stamp,
                                         round(frame * 1e9 / fps))
            for event in events:
                (LOG.info if event.kind == 'agrees' else LOG.warning)(event.message)
            yield frame, stamp, tracks
            tick()


def run_live(live, seq, fps: float, smoothed: bool = False, progress: bool = False
             ) -> Iterator[Tuple[int, float, list]]:
    """
    Yield what ``fusion_node`` publishes for ``seq``: ``(frame, stamp, tracks)``.

    Every frame is one set of ``live`` (``core.live.loop.LiveFusion``, the node's own live core:
    ``Fusion.step``, coasting, the publication policy), stamped as in ``run_fusion``.
    ``smoothed``: its ``~/tracks_smoothed`` (the frames still held at the end flushed), else
    its ``~/tracks``.
    """
    frames = {}                      # stamp [ns] -> frame number, until yielded
    with _progress(len(seq.frames), progress) as tick:
        for frame in seq.frames:
            stamp_ns = round(frame * 1e9 / fps)
            frames[stamp_ns] = frame
            views = seq.read(frame)
            missing = [c for c in live.camera_ids if c not in views]
            for pub in live.step_set(views, stamp_ns, frame / fps, missing):
                if pub.smoothed == smoothed:
                    yield frames.pop(pub.stamp_ns), pub.stamp, pub.tracks
            tick()
    for pub in live.flush():
        yield frames.pop(pub.stamp_ns), pub.stamp, pub.tracks


def run(args) -> int:
    """Track, write the JSON Lines file, print a summary; return the exit code."""
    from mv3dpose_ros.core.geometry.calibration import CalibrationError, save_rig_yaml
    from mv3dpose_ros.core.fusion.pipeline import Fusion, FusionConfig
    from mv3dpose_ros.core.tracking.hindsight import settle_tracks
    from mv3dpose_ros.core.live.config import complete_live_config
    from mv3dpose_ros.core.live.loop import LiveFusion
    from mv3dpose_ros.core.skeleton import get_layout
    from mv3dpose_ros.core.tracking.smoothing import smooth_track_sequence
    from mv3dpose_ros.core.live.sync import SyncConfig
    from mv3dpose_ros.core.selfcal.watch import CalibrationWatch, WatchConfig
    from mv3dpose_ros.core.types import JointState, TrackState
    from mv3dpose_ros.io.tracks_jsonl import TracksWriter
    import numpy as np

    logging.basicConfig(level=logging.WARNING, format='%(levelname)s %(name)s: %(message)s')
    if not args.fps > 0:
        print(f'mv3dpose track: --fps must be positive, got {args.fps}', file=sys.stderr)
        return 2
    try:
        layout = get_layout(args.layout)
        params = load_fusion_params(args.params) if args.params else {}
        if args.lag_frames < 0:
            raise ValueError(f'--lag-frames must be >= 0, got {args.lag_frames}')
        if args.smooth in ('offline', 'none'):
            params['smoothing'] = 'none'
        else:
            params['smoothing'] = 'causal'      # also under fixed-lag, as in fusion_node
        config = FusionConfig(**params)
        cameras, seq, notes = open_inputs(args)
        live = fusion = None
        lag = args.lag_frames if args.smooth == 'fixed-lag' else 0
        if args.smooth in ('causal', 'fixed-lag'):     # fusion_node's live core
            # Frames are sets already (step_set): their stamps follow no arrival clock, as
            # under sim time, and what completing changes concerns only the synchroniser.
            sync, config, _ = complete_live_config(SyncConfig(), config, sim_time=True)
            live = LiveFusion(list(cameras), layout, sync, config, lag=lag)
            live.start(cameras)
        else:
            fusion = Fusion(cameras, layout.name, config)
            watch = CalibrationWatch(cameras, WatchConfig.of(config))
    except (CalibrationError, ValueError, FileNotFoundError, OSError, TypeError) as e:
        print(f'mv3dpose track: {e}', file=sys.stderr)
        return 2
    for note in notes:
        print(f'mv3dpose track: warning: {note}; that camera is not used', file=sys.stderr)
    print(f'mv3dpose track: {len(seq)} frames (numbers {seq.frames[0]}..{seq.frames[-1]}), '
          f'cameras {", ".join(cameras)}, layout {layout.name}, {args.fps:g} fps, '
          f'smoothing {args.smooth}', file=sys.stderr)
    progress = not args.no_progress and sys.stderr.isatty()
    confirmed, reproj = set(), []
    t0 = time.perf_counter()
    try:
        if args.output != '-' and os.path.dirname(os.path.abspath(args.output)):
            os.makedirs(os.path.dirname(os.path.abspath(args.output)), exist_ok=True)
        with _output(args.output) as out, TracksWriter(out, layout.name) as writer:
            if live is not None:       # ~/tracks, or ~/tracks_smoothed with a lag
                frames = run_live(live, seq, args.fps, lag > 0, progress)
            else:
                frames = run_fusion(fusion, watch, seq, args.fps, progress)
            if args.smooth == 'offline':
                done = list(frames)
                settled = settle_tracks([t for _, _, t in done], [s for _, s, _ in done],
                                        max_gap_s=config.max_coast_s)
                smoothed = smooth_track_sequence(settled, args.sigma_frames,
                                                 args.max_gap_frames, layout.root_joints)
                # Predictions in gaps too long to interpolate have no joint left: not a pose.
                smoothed = [[t for t in f if t.state == TrackState.DELETED or t.valid.any()]
                            for f in smoothed]
                frames = ((f, s, t) for (f, s, _), t in zip(done, smoothed))
            for frame, stamp, tracks in frames:
                writer.write(frame, tracks, stamp)
                for t in tracks:
                    if t.state == TrackState.CONFIRMED:
                        confirmed.add(t.track_id)
                        err = t.reprojection_error[t.joint_state == JointState.TRIANGULATED]
                        reproj.extend(err[np.isfinite(err)].tolist())
    except OSError as e:
        print(f'mv3dpose track: cannot write {args.output}: {e}', file=sys.stderr)
        return 1
    elapsed = time.perf_counter() - t0
    if args.save_rig:
        try:
            save_rig_yaml(dict(live.cameras if live is not None else watch.cameras),
                          args.save_rig)
        except OSError as e:
            print(f'mv3dpose track: cannot write {args.save_rig}: {e}', file=sys.stderr)
            return 1
        print(f'mv3dpose track: wrote the rig in use to {args.save_rig}', file=sys.stderr)
    med = f'{np.median(reproj):.1f} px' if reproj else 'n/a'
    print(f'mv3dpose track: wrote {len(seq)} frames to {args.output} in {elapsed:.2f} s '
          f'({1000 * elapsed / max(len(seq), 1):.2f} ms/frame); confirmed tracks: '
          f'{len(confirmed)} (ids {sorted(confirmed)}); median reprojection error of '
          f'confirmed joints {med}', file=sys.stderr)
    if seq.issues:
        print(f'mv3dpose track: skipped {len(seq.issues)} file(s):', file=sys.stderr)
        for issue in seq.issues[:20]:
            print(f'  {issue}', file=sys.stderr)
        if len(seq.issues) > 20:
            print(f'  ... and {len(seq.issues) - 20} more', file=sys.stderr)
        return 3      # done, but input was skipped: scripts must notice
    return 0


@contextlib.contextmanager
def _output(path: str):
    """Yield standard output for '-', else a temp file renamed onto ``path`` on success."""
    from mv3dpose_ros.core.files import atomic_path
    if path == '-':
        yield sys.stdout
        return
    with atomic_path(path) as tmp:
        yield tmp
