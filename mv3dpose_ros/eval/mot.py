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
Multi-object tracking scores of 3D pose tracks: CLEAR MOT (MOTA, MOTP), IDF1, ID switches.

Frame by frame, ground-truth people and hypothesis tracks (each with an id and a ``[J, 3]``
pose in metres, NaN for missing joints) are matched with the CLEAR MOT rules of the
``motmetrics`` library: a pair can match only when its distance is below ``threshold_m``;
correspondences of the previous frame are kept while still valid, the rest is solved by the
Hungarian algorithm, and a ground-truth id whose hypothesis id changes counts an ID switch.
The distance is the mean joint distance over shared joints (``'mean_joint'``) or the distance
of the roots (``'root'``: mean of ``root_joints``, by default the centroid of valid joints).
"""

from dataclasses import asdict, dataclass
from typing import Iterable, Optional, Sequence, Tuple

import motmetrics as mm
from mv3dpose_ros.eval.mpjpe import pose_distances
import numpy as np

_METRICS = ['num_frames', 'mota', 'motp', 'idf1', 'idp', 'idr', 'num_switches',
            'num_false_positives', 'num_misses', 'num_objects', 'num_matches',
            'mostly_tracked', 'mostly_lost', 'num_unique_objects', 'num_fragmentations']


@dataclass
class MOTResult:
    """Sequence-level tracking scores (distances in metres)."""

    mota: float
    motp_m: float            # mean distance of matched pairs
    idf1: float
    idp: float
    idr: float
    id_switches: int
    false_positives: int
    misses: int
    num_objects: int         # ground-truth person-frames
    num_matches: int
    mostly_tracked: int
    mostly_lost: int
    num_unique_objects: int
    fragmentations: int
    frames: int

    def as_dict(self) -> dict:
        """Return the scores as a plain dict (JSON friendly)."""
        return asdict(self)

    def summary(self) -> str:
        """Format the scores on two lines."""
        return (f'MOTA {100 * self.mota:.1f}  IDF1 {100 * self.idf1:.1f}  '
                f'ID switches {self.id_switches}  MOTP {1000 * self.motp_m:.1f} mm\n'
                f'FP {self.false_positives}  FN {self.misses}  GT {self.num_objects}  '
                f'frames {self.frames}  mostly tracked {self.mostly_tracked}/'
                f'{self.num_unique_objects}')


def _roots(poses: np.ndarray, root_joints: Optional[Sequence[int]]) -> np.ndarray:
    sel = poses[:, list(root_joints)] if root_joints else poses
    with np.errstate(invalid='ignore'):
        valid = np.isfinite(sel).all(-1)
        count = valid.sum(-1)
        total = np.where(valid[..., None], sel, 0.0).sum(-2)
        if root_joints:   # a root needs all its joints (e.g. both hips)
            return np.where((count == len(root_joints))[:, None], total / len(root_joints),
                            np.nan)
        return np.where((count > 0)[:, None], total / np.maximum(count, 1)[:, None], np.nan)


class MOTEvaluator:
    """Accumulate frames of ground truth and hypotheses, then compute :class:`MOTResult`."""

    def __init__(self, threshold_m: float = 0.5, distance: str = 'mean_joint',
                 root_joints: Optional[Sequence[int]] = None):
        """Set the match threshold (m) and the distance ('mean_joint' or 'root')."""
        if distance not in ('mean_joint', 'root'):
            raise ValueError(f"distance must be 'mean_joint' or 'root', not {distance!r}")
        if not threshold_m > 0:
            raise ValueError(f'threshold_m must be positive, got {threshold_m}')
        self.threshold_m = float(threshold_m)
        self.distance = distance
        self.root_joints = tuple(root_joints) if root_joints else None
        self._acc = mm.MOTAccumulator(auto_id=True)

    def distances(self, gt: np.ndarray, hyp: np.ndarray) -> np.ndarray:
        """Return the ``[G, H]`` distance matrix, NaN where a match is not allowed."""
        if self.distance == 'root':
            d = pose_distances(_roots(gt, self.root_joints)[:, None],
                               _roots(hyp, self.root_joints)[:, None])
        else:
            d = pose_distances(gt, hyp)
        return np.where(np.isfinite(d) & (d < self.threshold_m), d, np.nan)

    def update(self, gt_ids: Sequence[int], gt_poses: np.ndarray,
               hyp_ids: Sequence[int], hyp_poses: np.ndarray) -> None:
        """Add one frame: ids and ``[N, J, 3]`` poses of ground truth and hypotheses."""
        gt_ids = [int(i) for i in gt_ids]
        hyp_ids = [int(i) for i in hyp_ids]
        if len(set(gt_ids)) != len(gt_ids) or len(set(hyp_ids)) != len(hyp_ids):
            raise ValueError(f'duplicate ids in one frame: gt {gt_ids}, hyp {hyp_ids}')
        gt = np.asarray(gt_poses, dtype=float)
        hyp = np.asarray(hyp_poses, dtype=float)
        if len(gt_ids) and len(hyp_ids):
            d = self.distances(gt.reshape(len(gt_ids), -1, 3), hyp.reshape(len(hyp_ids), -1, 3))
        else:
            d = np.zeros((len(gt_ids), len(hyp_ids)))
        self._acc.update(gt_ids, hyp_ids, d)

    def result(self) -> MOTResult:
        """Compute the scores of all frames added so far."""
        mh = mm.metrics.create()
        s = mh.compute(self._acc, metrics=_METRICS, name='seq').iloc[0]

        def num(key: str) -> float:
            v = float(s[key])
            return v if np.isfinite(v) else float('nan')

        return MOTResult(
            mota=num('mota'), motp_m=num('motp'), idf1=num('idf1'), idp=num('idp'),
            idr=num('idr'), id_switches=int(s['num_switches']),
            false_positives=int(s['num_false_positives']), misses=int(s['num_misses']),
            num_objects=int(s['num_objects']), num_matches=int(s['num_matches']),
            mostly_tracked=int(s['mostly_tracked']), mostly_lost=int(s['mostly_lost']),
            num_unique_objects=int(s['num_unique_objects']),
            fragmentations=int(s['num_fragmentations']), frames=int(s['num_frames']))


def evaluate_mot(frames: Iterable[Tuple[Sequence[int], np.ndarray, Sequence[int], np.ndarray]],
                 threshold_m: float = 0.5, distance: str = 'mean_joint',
                 root_joints: Optional[Sequence[int]] = None) -> MOTResult:
    """Score frames of ``(gt_ids, gt_poses [G,J,3], hyp_ids, hyp_poses [H,J,3])``."""
    ev = MOTEvaluator(threshold_m, distance, root_joints)
    for gt_ids, gt_poses, hyp_ids, hyp_poses in frames:
        ev.update(gt_ids, gt_poses, hyp_ids, hyp_poses)
    return ev.result()
