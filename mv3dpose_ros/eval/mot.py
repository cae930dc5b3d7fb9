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
Multi-object tracking scores of 3D pose tracks: CLEAR MOT, IDF1/IDP/IDR, switches, duplicates.

Frame by frame, ground-truth people and hypothesis tracks (each with an id and a ``[J, 3]``
pose in metres, NaN for missing joints) are matched with the CLEAR MOT rules of the
``motmetrics`` library: a pair can match only when its distance is below ``threshold_m``;
correspondences of the previous frame are kept while still valid, the rest is solved by the
Hungarian algorithm, and a ground-truth id whose hypothesis id changes counts an ID switch.
The distance is the mean joint distance over shared joints (``'mean_joint'``) or the distance
of the roots (``'root'``: mean of ``root_joints``, by default the centroid of valid joints).

API::

    ev = MOTEvaluator(threshold_m=0.5, distance='mean_joint', root_joints=None, fps=None)
    ev.update(gt_ids, gt_poses [G,J,3], hyp_ids, hyp_poses [H,J,3], stamp=None)  # per frame
    res = ev.result()                          # -> MOTResult
    res = evaluate_mot(frames, ...)            # the same over (gt_ids, gt, hyp_ids, hyp[, stamp])

Identity figures of :class:`MOTResult`, beside MOTA/MOTP:

- ``idf1``, ``idp``, ``idr``: identity F1, precision and recall (Ristani et al. 2016), with
  one global one-to-one id mapping over the whole sequence, so an id that follows a person
  only for a while earns only those frames (``motmetrics``' implementation).
- ``id_switches_per_min``: ID switches per minute of evaluated frames, which makes runs of
  different lengths comparable. The duration is ``frames / fps`` with ``fps``, else
  ``frames`` times the median step of the frame stamps passed to ``update``
  (:func:`.identity.sequence_duration`); NaN without either.
- ``fragmentations``: times a ground-truth trajectory goes from tracked to untracked and
  comes back tracked (CLEAR MOT, ``motmetrics``' ``num_fragmentations``); an ID switch
  without a gap is not a fragmentation.
- ``duplicates``, ``duplicate_rate``: ground-truth person-frames with more than one
  hypothesis within ``threshold_m`` (a person published twice), and their share of all
  ground-truth person-frames. The hypotheses are those given to ``update``, so pass the
  confirmed tracks only to score what a consumer sees.

Figures that need no ground truth (live rigs) are in :mod:`.identity`.
"""

from dataclasses import asdict, dataclass
import math
from typing import Iterable, List, Optional, Sequence, Tuple, Union

import motmetrics as mm
from mv3dpose_ros.eval.identity import sequence_duration
from mv3dpose_ros.eval.mpjpe import pose_distances, pose_roots
import numpy as np

_METRICS = ['num_frames', 'mota', 'motp', 'idf1', 'idp', 'idr', 'num_switches',
            'num_false_positives', 'num_misses', 'num_objects', 'num_matches',
            'mostly_tracked', 'mostly_lost', 'num_unique_objects', 'num_fragmentations']

MOTFrame = Union[Tuple[Sequence[int], np.ndarray, Sequence[int], np.ndarray],
                 Tuple[Sequence[int], np.ndarray, Sequence[int], np.ndarray, Optional[float]]]


@dataclass
class MOTResult:
    """Sequence-level tracking scores (distances in metres, NaN where undefined)."""

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
    duplicates: int = 0                         # GT person-frames with > 1 hypothesis near
    duplicate_rate: float = float('nan')        # duplicates / num_objects
    duration_s: float = float('nan')            # evaluated frames times the frame period
    id_switches_per_min: float = float('nan')

    def as_dict(self) -> dict:
        """Return the scores as a plain dict (strict JSON: NaN becomes ``None``)."""
        return {k: None if isinstance(v, float) and not math.isfinite(v) else v
                for k, v in asdict(self).items()}

    def summary(self) -> str:
        """Format the scores on three lines."""
        per_min = ('' if not math.isfinite(self.id_switches_per_min)
                   else f' ({self.id_switches_per_min:.2f}/min)')
        return (f'MOTA {100 * self.mota:.1f}  IDF1 {100 * self.idf1:.1f}  '
                f'ID switches {self.id_switches}{per_min}  MOTP {1000 * self.motp_m:.1f} mm\n'
                f'FP {self.false_positives}  FN {self.misses}  GT {self.num_objects}  '
                f'frames {self.frames}  mostly tracked {self.mostly_tracked}/'
                f'{self.num_unique_objects}\n'
                f'IDP {100 * self.idp:.1f}  IDR {100 * self.idr:.1f}  '
                f'fragmentations {self.fragmentations}  duplicates {self.duplicates} '
                f'({100 * self.duplicate_rate:.1f} % of GT)')


class MOTEvaluator:
    """Accumulate frames of ground truth and hypotheses, then compute :class:`MOTResult`."""

    def __init__(self, threshold_m: float = 0.5, distance: str = 'mean_joint',
                 root_joints: Optional[Sequence[int]] = None, fps: Optional[float] = None):
        """
        Set the match threshold (m), the distance ('mean_joint' or 'root') and the frame rate.

        ``fps`` gives the duration for ID switches per minute; without it the stamps passed
        to :meth:`update` do.
        """
        if distance not in ('mean_joint', 'root'):
            raise ValueError(f"distance must be 'mean_joint' or 'root', not {distance!r}")
        if not threshold_m > 0:
            raise ValueError(f'threshold_m must be positive, got {threshold_m}')
        if fps is not None and not (math.isfinite(fps) and fps > 0):
            raise ValueError(f'fps must be positive, got {fps}')
        self.threshold_m = float(threshold_m)
        self.distance = distance
        self.root_joints = tuple(root_joints) if root_joints else None
        self.fps = None if fps is None else float(fps)
        self._acc = mm.MOTAccumulator(auto_id=True)
        self._stamps: List[float] = []
        self._duplicates = 0

    def distances(self, gt: np.ndarray, hyp: np.ndarray) -> np.ndarray:
        """Return the ``[G, H]`` distance matrix, NaN where a match is not allowed."""
        if self.distance == 'root':
            d = pose_distances(pose_roots(gt, self.root_joints)[:, None],
                               pose_roots(hyp, self.root_joints)[:, None])
        else:
            d = pose_distances(gt, hyp)
        return np.where(np.isfinite(d) & (d < self.threshold_m), d, np.nan)

    def update(self, gt_ids: Sequence[int], gt_poses: np.ndarray,
               hyp_ids: Sequence[int], hyp_poses: np.ndarray,
               stamp: Optional[float] = None) -> None:
        """Add one frame: ids and ``[N, J, 3]`` poses of ground truth and hypotheses."""
        gt_ids = [int(i) for i in gt_ids]
        hyp_ids = [int(i) for i in hyp_ids]
        if len(set(gt_ids)) != len(gt_ids) or len(set(hyp_ids)) != len(hyp_ids):
            raise ValueError(f'duplicate ids in one frame: gt {gt_ids}, hyp {hyp_ids}')
        gt = np.asarray(gt_poses, dtype=float)
        hyp = np.asarray(hyp_poses, dtype=float)
        if len(gt_ids) and len(hyp_ids):
            d = self.distances(gt.reshape(len(gt_ids), -1, 3), hyp.reshape(len(hyp_ids), -1, 3))
            self._duplicates += int((np.isfinite(d).sum(1) > 1).sum())
        else:
            d = np.zeros((len(gt_ids), len(hyp_ids)))
        self._acc.update(gt_ids, hyp_ids, d)
        if stamp is not None:
            self._stamps.append(float(stamp))

    def result(self) -> MOTResult:
        """Compute the scores of all frames added so far."""
        mh = mm.metrics.create()
        s = mh.compute(self._acc, metrics=_METRICS, name='seq').iloc[0]

        def num(key: str) -> float:
            v = float(s[key])
            return v if np.isfinite(v) else float('nan')

        frames = int(s['num_frames'])
        objects = int(s['num_objects'])
        switches = int(s['num_switches'])
        duration = sequence_duration(self._stamps, frames, self.fps)
        return MOTResult(
            mota=num('mota'), motp_m=num('motp'), idf1=num('idf1'), idp=num('idp'),
            idr=num('idr'), id_switches=switches,
            false_positives=int(s['num_false_positives']), misses=int(s['num_misses']),
            num_objects=objects, num_matches=int(s['num_matches']),
            mostly_tracked=int(s['mostly_tracked']), mostly_lost=int(s['mostly_lost']),
            num_unique_objects=int(s['num_unique_objects']),
            fragmentations=int(s['num_fragmentations']), frames=frames,
            duplicates=self._duplicates,
            duplicate_rate=self._duplicates / objects if objects else float('nan'),
            duration_s=duration,
            id_switches_per_min=60.0 * switches / duration if duration > 0 else float('nan'))


def evaluate_mot(frames: Iterable[MOTFrame], threshold_m: float = 0.5,
                 distance: str = 'mean_joint', root_joints: Optional[Sequence[int]] = None,
                 fps: Optional[float] = None) -> MOTResult:
    """Score frames of ``(gt_ids, gt_poses [G,J,3], hyp_ids, hyp_poses [H,J,3][, stamp_s])``."""
    ev = MOTEvaluator(threshold_m, distance, root_joints, fps)
    for frame in frames:
        ev.update(*frame)
    return ev.result()
