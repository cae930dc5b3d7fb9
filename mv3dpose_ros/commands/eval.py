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
``mv3dpose eval``: score a tracks JSON Lines file against ground truth.

Prints PCP3D (10 parts and 8 limbs, per actor, alpha 0.5, the VoxelPose protocol), MPJPE with
Hungarian matching, CLEAR MOT (MOTA, MOTP, ID switches and per minute, fragmentations), IDF1
with IDP and IDR, the share of ground-truth person-frames with two hypotheses on them
(duplicates), and the identity figures a live run gets without ground truth
(``eval.identity.identity_summary``: distinct ids, share of the N most frequent, returns, late
ids, over-count, duplicates), all also in the ``--json`` file. Ground-truth formats:
``campus`` (Campus/Shelf ``actorsGT.mat``, default frames the Campus test frames 350-470 and
650-750), ``shelf`` (same file format, all annotated frames), ``panoptic`` (a folder of
Panoptic ``body3DScene_*.json``) and ``tracks`` (ground truth in the tracks JSON Lines schema,
e.g. from ``mv3dpose_ros.sim.export``). Frame numbers of both files must agree, up to
``--frame-offset``.
"""

import argparse
import json
import math
import sys
from typing import Dict, List, Optional

from mv3dpose_ros.core.files import atomic_path
from mv3dpose_ros.core.geometry.camera import CalibrationError
from mv3dpose_ros.core.types import TrackState
from mv3dpose_ros.eval.sequence import evaluate_run, load_ground_truth, read_hypotheses
from mv3dpose_ros.io.datasets import DatasetError


def parse_frames(text: str) -> List[int]:
    """Parse '350-470,650-750,800' into a sorted list of frame numbers (ranges inclusive)."""
    out = set()
    for part in text.split(','):
        part = part.strip()
        if not part:
            continue
        try:
            if '-' in part[1:]:
                a, b = part.split('-', 1) if not part.startswith('-') else (part, part)
                lo, hi = int(a), int(b)
                if hi < lo:
                    raise ValueError
                out.update(range(lo, hi + 1))
            else:
                out.add(int(part))
        except ValueError:
            raise argparse.ArgumentTypeError(
                f'bad frame list {text!r}: use numbers and inclusive ranges like '
                f'350-470,650-750') from None
    return sorted(out)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the options of ``mv3dpose eval``."""
    parser.add_argument('--tracks', required=True, metavar='FILE',
                        help='tracks JSON Lines written by mv3dpose track')
    parser.add_argument('--gt', required=True, metavar='FILE_OR_DIR',
                        help='ground truth: actorsGT.mat (or its folder), a Panoptic '
                             'hdPose3d folder, or a tracks JSON Lines file')
    parser.add_argument('--format', required=True,
                        choices=('campus', 'shelf', 'panoptic', 'tracks'),
                        help='ground-truth format')
    parser.add_argument('--frames', type=parse_frames, metavar='LIST',
                        help='frames to score, e.g. 350-470,650-750 (default: the dataset '
                             'test frames for campus, else every ground-truth frame)')
    parser.add_argument('--frame-offset', type=int, default=0,
                        help='tracks frame = ground-truth frame + offset (default 0)')
    parser.add_argument('--states', default='confirmed,coasting',
                        help='comma-separated track states counted as predictions (default: '
                             'confirmed,coasting: every track the tracker believes in; '
                             'also tentative)')
    parser.add_argument('--threshold-m', type=float, default=0.5,
                        help='match distance for MOT and MPJPE, metres (default 0.5)')
    parser.add_argument('--mot-distance', choices=('mean_joint', 'root'), default='mean_joint',
                        help='MOT distance: mean joint distance or hip-midpoint distance')
    parser.add_argument('--alpha', type=float, default=0.5, help='PCP alpha (default 0.5)')
    parser.add_argument('--pcp-matching', choices=('nearest', 'hungarian'), default='nearest',
                        help='PCP: nearest prediction per actor (VoxelPose) or one-to-one')
    parser.add_argument('--fps', type=float, metavar='HZ',
                        help='frame rate: tracks frame n is at n / fps s, for ID switches per '
                             'minute and the identity warm-up (default: the stamps of the '
                             'tracks lines)')
    parser.add_argument('--duplicate-radius-m', type=float, default=0.3, metavar='M',
                        help='identity without GT: two confirmed skeletons closer than this '
                             '(mean joint distance) are one person twice (default 0.3)')
    parser.add_argument('--json', metavar='FILE', help='also write the figures as JSON')


def _states(text: str):
    names = [s.strip().lower() for s in text.split(',') if s.strip()]
    known = {s.name.lower(): s for s in TrackState if s != TrackState.DELETED}
    bad = [n for n in names if n not in known]
    if bad or not names:
        raise ValueError(f'--states: unknown state(s) {bad or text!r}; known: '
                         f'{", ".join(known)}')
    return [known[n] for n in names]


def run(args) -> int:
    """Load both files, score, print; return the exit code."""
    issues: List[str] = []
    stamps: Dict[int, float] = {}
    try:
        states = _states(args.states)
        if not args.threshold_m > 0 or not args.alpha > 0 or not args.duplicate_radius_m > 0:
            raise ValueError('--threshold-m, --alpha and --duplicate-radius-m must be positive')
        if args.fps is not None and not (math.isfinite(args.fps) and args.fps > 0):
            raise ValueError(f'--fps must be positive, got {args.fps}')
        gt = load_ground_truth(args.gt, args.format)
        layout, hyps = read_hypotheses(args.tracks, states, issues, stamps)
        if layout is None:
            if not hyps:
                raise ValueError(f'{args.tracks}: no usable lines')
            raise ValueError(f'{args.tracks}: the lines carry no "layout"')
        report = evaluate_run(layout, hyps, gt, args.frames, args.frame_offset,
                              args.threshold_m, args.mot_distance, args.alpha,
                              args.pcp_matching, stamps, args.fps, args.duplicate_radius_m)
    except (OSError, ValueError, DatasetError, CalibrationError) as e:
        print(f'mv3dpose eval: {e}', file=sys.stderr)
        return 2
    for issue in issues[:20]:
        print(f'mv3dpose eval: skipped {issue}', file=sys.stderr)
    if report.frames == 0:
        print('mv3dpose eval: no ground-truth frame to evaluate (check --frames)',
              file=sys.stderr)
        return 1
    print(f'tracks {args.tracks} ({layout}, states {args.states}) vs {args.format} ground '
          f'truth {args.gt} ({gt.layout})')
    print(report.text())
    if args.json:
        out: Optional[dict] = report.as_dict()
        try:
            with atomic_path(args.json) as tmp, open(tmp, 'w', encoding='utf-8') as f:
                json.dump(out, f, indent=2)
        except OSError as e:
            print(f'mv3dpose eval: cannot write {args.json}: {e}', file=sys.stderr)
            return 1
    skipped = issues + [n for n in gt.notes if n.startswith(('skipped ', f'{args.gt}:'))]
    if skipped:
        print(f'mv3dpose eval: {len(skipped)} malformed input(s) skipped; the figures leave '
              'them out', file=sys.stderr)
        return 3
    return 0
