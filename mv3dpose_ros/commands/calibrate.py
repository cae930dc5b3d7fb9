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
``mv3dpose calibrate``: a rig's extrinsics from the 2D keypoints of the people moving in it.

Intrinsics come from ``--calibration`` (any format ``core.geometry.calibration`` reads; its
extrinsics give at most the world frame, unless ``--refine``) or, with ``--bag``, from the bag's
CameraInfo where ``--calibration`` is not given. Keypoints come from per-camera OpenPose JSON
folders (``--poses``, as ``mv3dpose track``) or from a bag of ``Person2DArray`` messages
(``--bag``, e.g. recorded from the live rig with ``mv3dpose bag record``). The estimation is
``core.selfcal.extrinsics`` (pairwise person matching and essential matrices, incremental
placement, bundle adjustment); the world frame is ``--calibration``'s where its extrinsics are
credible (``--frame auto``: ``core.selfcal.extrinsics.adopt_frame``), else the floor under the
people with metres from a person height prior.

Output: the rig YAML (``-o``) every command and ``fusion_node`` read, a text report printed
and written beside it (``RIG.report.txt``) and a picture of the rig (``RIG.png``).
Exit status: 0 done; 2 bad input (too few people or frames, people standing still,
intrinsics missing, unreadable files), nothing written; 3 done without some cameras (they
never shared people with the others; the report says which and why); 1 cannot write.
"""

import argparse
import os
import sys
from typing import Dict, List, Optional, Tuple

from mv3dpose_ros.io.pose_inputs import add_image_size_argument

PERSONS_TYPE = 'mv3dpose_msgs/msg/Person2DArray'
INFO_TYPE = 'sensor_msgs/msg/CameraInfo'


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``mv3dpose calibrate``."""
    parser.add_argument('--calibration', metavar='FILE',
                        help='intrinsics: a rig YAML or any calibration format (its '
                             'extrinsics are ignored unless --refine); optional with --bag '
                             'holding CameraInfo')
    parser.add_argument('--calibration-format', default='auto',
                        help='calibration format (default: auto-detect)')
    add_image_size_argument(parser)
    src = parser.add_mutually_exclusive_group(required=True)
    src.add_argument('--poses', metavar='ROOT',
                     help='folder with one OpenPose JSON folder per camera')
    src.add_argument('--bag', metavar='BAG',
                     help='a bag of Person2DArray topics (+ CameraInfo), e.g. from '
                          'mv3dpose bag record')
    parser.add_argument('--layout', help='joint layout of the detections (body25, body25b, '
                                         'coco17, ...; --bag: default from the messages)')
    parser.add_argument('--output', '-o', required=True, metavar='RIG.yaml',
                        help='the calibrated rig YAML')
    parser.add_argument('--cameras', nargs='+', metavar='NAME', help='use only these cameras')
    parser.add_argument('--refine', action='store_true',
                        help="start from --calibration's extrinsics and report how far each "
                             'camera moved (the cameras that moved least hold the frame)')
    parser.add_argument('--person-height', type=float, default=None, metavar='M',
                        help='stature of the people, for metres (default 1.70, an adult '
                             'median)')
    parser.add_argument('--baseline', nargs=3, metavar=('CAM_A', 'CAM_B', 'METRES'),
                        help='metres from a measured distance between two camera centres')
    parser.add_argument('--origin-camera', metavar='NAME',
                        help='world origin on the floor under this camera (default: under '
                             "the people's mean position)")
    parser.add_argument('--min-confidence', type=float, default=0.3,
                        help='keypoints below this confidence are not used (default 0.3)')
    parser.add_argument('--max-frames', type=int, default=600,
                        help='use at most this many frames, evenly spread (default 600)')
    parser.add_argument('--frame', choices=('auto', 'calibration', 'people'), default='auto',
                        help="world frame: calibration = --calibration's (its credible "
                             'extrinsics give only the frame: a similarity), people = z up '
                             'from the floor under the people; auto (default): calibration '
                             'where its extrinsics are credible and neither --baseline nor '
                             '--origin-camera is given, else people')
    parser.add_argument('--no-picture', action='store_true', help='do not draw RIG.png')


def read_bag(path: str, num_joints: Optional[int] = None
             ) -> Tuple[List[Tuple[int, Dict[str, object]]], Dict[str, dict], Optional[str]]:
    """
    Read a bag's Person2DArray and CameraInfo messages.

    Returns ``(sets, infos, layout)``: the people of every camera grouped into sets of one
    instant (stamps within half the median message period of a camera), CameraInfo fields per
    camera, and the layout the messages name.
    """
    import numpy as np

    from mv3dpose_ros.io.bag import BagReader, get_typestore
    from mv3dpose_ros.ros.messages import decode_person2d_array, person2d_array_to_numpy

    store = get_typestore()
    msgs, infos, layout = [], {}, None
    with BagReader(path) as reader:
        kinds = {t: s.msgtype for t, s in reader.topics().items()}
        wanted = [t for t, k in kinds.items() if k in (PERSONS_TYPE, INFO_TYPE)]
        if not any(kinds[t] == PERSONS_TYPE for t in wanted):
            raise ValueError(f'{path}: no {PERSONS_TYPE} topic (topics: '
                             f'{", ".join(sorted(kinds)) or "none"})')
        for m in reader.messages(wanted):
            cam = m.topic.strip('/').split('/')[0]
            if m.msgtype == INFO_TYPE:
                info = store.deserialize_cdr(m.data, m.msgtype)
                infos[info.header.frame_id or cam] = {
                    'K': np.asarray(info.k, float).reshape(3, 3), 'dist': np.asarray(info.d),
                    'width': int(info.width), 'height': int(info.height)}
                continue
            people = decode_person2d_array(m.data)
            name = people.camera_id or people.frame_id or cam
            layout = layout or people.layout or None
            msgs.append((people.stamp_ns or m.timestamp, name,
                         person2d_array_to_numpy(people, num_joints)))
    msgs.sort(key=lambda x: x[0])
    periods = []
    for cam in {c for _, c, _ in msgs}:
        stamps = np.array([s for s, c, _ in msgs if c == cam])
        if len(stamps) > 1:
            periods.append(np.median(np.diff(stamps)))
    tol = 0.5 * float(np.median(periods)) if periods else 0.0
    sets, start = [], None
    for stamp, cam, poses in msgs:
        if start is None or cam in sets[-1][1] or stamp - start > tol:
            sets.append((stamp, {}))
            start = stamp
        sets[-1][1][cam] = poses
    return sets, infos, layout


def _intrinsics(args, bag_infos: Dict[str, dict], names: List[str]) -> dict:
    """Return camera -> Camera (intrinsics) from --calibration, else the bag's CameraInfo."""
    import numpy as np

    from mv3dpose_ros.core.geometry.camera import Camera
    from mv3dpose_ros.core.selfcal.views import SelfCalError
    from mv3dpose_ros.io.pose_inputs import load_rig

    given = load_rig(args) if args.calibration else {}
    out = {}
    for n in names:
        if n in given:
            out[n] = given[n]
        elif n in bag_infos:
            i = bag_infos[n]
            out[n] = Camera(n, i['K'], i['dist'], np.eye(3), np.zeros(3), i['width'],
                            i['height'])
    missing = [n for n in names if n not in out]
    if missing:
        where = f'not in {args.calibration}' if args.calibration else 'no --calibration'
        raise SelfCalError(f'intrinsics missing for camera(s) {", ".join(missing)}: {where} '
                           'and no CameraInfo for them in the bag')
    return out


def _unmatched_folders(root: str, cameras) -> List[str]:
    """Return the sub-folders of ``root`` that no calibrated camera matched."""
    from mv3dpose_ros.io.openpose import match_camera_folders
    folders, _ = match_camera_folders(root, list(cameras))
    used = {os.path.basename(p) for p in folders.values()}
    return sorted(d for d in os.listdir(root)
                  if os.path.isdir(os.path.join(root, d)) and d not in used)


def load_inputs(args):
    """Return ``(views, intrinsics, layout, given rig)`` or raise a typed error."""
    from mv3dpose_ros.core.selfcal.views import normalise_views, SelfCalError, Settings
    from mv3dpose_ros.core.skeleton import get_layout
    from mv3dpose_ros.io.pose_inputs import load_rig, open_inputs

    settings = Settings(min_confidence=args.min_confidence)
    if args.poses:
        if not args.calibration:
            raise SelfCalError('--poses needs --calibration for the intrinsics')
        if not args.layout:
            raise SelfCalError('--poses needs --layout')
        cameras, seq, notes = open_inputs(args)
        extra = [] if args.cameras else _unmatched_folders(args.poses, cameras)
        if extra:
            raise SelfCalError(f'intrinsics missing for the camera folder(s) '
                               f'{", ".join(extra)} in {args.poses}: no camera of '
                               f'{args.calibration} matches them (or pass --cameras)')
        layout = args.layout
        frames = list(seq.frames)
        frames = _spread(frames, args.max_frames)
        sets = ((f, seq.read(f)) for f in frames)
    else:
        sets, infos, bag_layout = read_bag(args.bag)
        layout = args.layout or bag_layout
        if not layout:
            raise SelfCalError(f'{args.bag}: the messages name no layout; pass --layout')
        names = sorted({c for _, v in sets for c in v})
        if args.cameras:
            names = [n for n in names if n in args.cameras]
        cameras = _intrinsics(args, infos, names)
        keep = _spread(list(range(len(sets))), args.max_frames)
        sets = [(k, {c: sets[k][1][c] for c in names if c in sets[k][1]}) for k in keep]
    num = get_layout(layout).num_joints
    views = normalise_views(sets, cameras, layout, settings)
    given = None
    if args.refine:
        if not args.calibration:
            raise SelfCalError('--refine needs --calibration with the rig to start from')
        given = load_rig(args)
        given = {n: given[n] for n in cameras}
    del num
    return views, cameras, layout, given, settings


def _spread(items: list, limit: int) -> list:
    if limit and len(items) > limit:
        step = -(-len(items) // limit)
        return items[::step]
    return items


def report_text(result, args, views, layout: str, picture: Optional[str]) -> str:
    """Return the report: world frame, per camera and per pair figures, unplaced cameras."""
    lines = [f'mv3dpose calibrate: {len(views.cameras)} cameras, {len(views.frames)} frames, '
             f'layout {layout}' + (' (refine)' if args.refine else ''),
             f'world frame: {result.world}', f'scale: {result.scale}', '',
             'camera        placed  joints  reproj median px  p95 px'
             + ('  moved deg  moved cm' if args.refine else '')]
    for n, r in result.reports.items():
        if r.placed:
            row = (f'{n:<13} yes    {r.observations:>7}  {r.median_px:>16.2f}  '
                   f'{r.p95_px:>6.2f}')
            if args.refine:
                row += f'  {r.moved_deg:>9.2f}  {100 * r.moved_m:>8.1f}'
        else:
            row = f'{n:<13} NO     {"-":>7}  ({r.why})'
        lines.append(row)
    lines += ['', 'pair                  person matches  joints fitting its essential matrix']
    for p in result.pairs:
        pair = f'{p.a}-{p.b}'
        note = f'  ({p.note})' if p.note else ''
        lines.append(f'{pair:<21} {p.person_frames:>14}  {p.inliers:>6} of '
                     f'{p.correspondences}{note}')
    if result.unplaced:
        lines += ['', 'not placed:'] + [f'  {n}: {w}' for n, w in result.unplaced.items()]
    if picture:
        lines += ['', f'picture: {picture}']
    return '\n'.join(lines) + '\n'


def run(args) -> int:
    """Calibrate, write the rig, the report and the picture; return the exit code."""
    from mv3dpose_ros.core.geometry.calibration import CalibrationError, save_rig_yaml
    from mv3dpose_ros.core.selfcal.extrinsics import adopt_frame, calibrate
    from mv3dpose_ros.core.selfcal.frame import ADULT_HEIGHT_M
    from mv3dpose_ros.core.selfcal.views import SelfCalError

    prog = 'mv3dpose calibrate'
    try:
        baseline = None
        if args.baseline:
            try:
                baseline = (args.baseline[0], args.baseline[1], float(args.baseline[2]))
            except ValueError:
                raise SelfCalError(f'--baseline METRES must be a number, got '
                                   f'{args.baseline[2]!r}') from None
            if not baseline[2] > 0:
                raise SelfCalError('--baseline METRES must be positive')
        height = args.person_height if args.person_height is not None else ADULT_HEIGHT_M
        if not 0.5 < height < 2.5:
            raise SelfCalError(f"--person-height {height} m is not a person's stature")
        views, cameras, layout, given, settings = load_inputs(args)
        for name in ([args.origin_camera] if args.origin_camera else []) + \
                (list(baseline[:2]) if baseline else []):
            if name not in cameras:
                raise SelfCalError(f'camera {name!r} is not among the cameras '
                                   f'{", ".join(cameras)}')
        print(f'{prog}: {len(views.frames)} frames, cameras {", ".join(cameras)}, '
              f'layout {layout}', file=sys.stderr)
        result = calibrate(views, cameras, layout, settings, initial=given,
                           person_height=height, baseline=baseline,
                           origin_camera=args.origin_camera,
                           log=lambda text: print(f'{prog}: {text}', file=sys.stderr))
    except (SelfCalError, CalibrationError, ValueError, FileNotFoundError, OSError,
            KeyError) as e:
        print(f'{prog}: {e}', file=sys.stderr)
        return 2
    if given is None and args.frame != 'people' and args.calibration and (
            args.frame == 'calibration' or not (baseline or args.origin_camera)):
        why = adopt_frame(result, cameras)
        if why:
            result.world += f' (not the frame of {args.calibration}: {why})'
            if args.frame == 'calibration':
                print(f'{prog}: --frame calibration: {why}', file=sys.stderr)
                return 2
    if args.person_height is not None and (given is not None or baseline):
        print(f'{prog}: note: --person-height is not used ({result.scale})', file=sys.stderr)
    rig = dict(result.cameras)
    if given is not None:
        for n in result.unplaced:
            rig[n] = given[n]             # kept as given, said in the report
    stem = os.path.splitext(args.output)[0]
    picture = None if args.no_picture else stem + '.png'
    text = report_text(result, args, views, layout, picture)
    try:
        if os.path.dirname(os.path.abspath(args.output)):
            os.makedirs(os.path.dirname(os.path.abspath(args.output)), exist_ok=True)
        save_rig_yaml(rig, args.output, comment=(
            f'calibrated by mv3dpose calibrate from the people in '
            f'{args.poses or args.bag}\n{result.world}\n{result.scale}'))
        with open(stem + '.report.txt', 'w', encoding='utf-8') as f:
            f.write(text)
        if picture:
            from mv3dpose_ros.viz.pictures import write_png
            from mv3dpose_ros.viz.rig import rig_picture
            write_png(rig_picture(result.cameras, result.points, result.point_person,
                                  unplaced=list(result.unplaced)), picture)
    except OSError as e:
        print(f'{prog}: cannot write {args.output}: {e}', file=sys.stderr)
        return 1
    sys.stdout.write(text)
    print(f'{prog}: wrote {args.output} and {stem}.report.txt', file=sys.stderr)
    return 3 if result.unplaced else 0
